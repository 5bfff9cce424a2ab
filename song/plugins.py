"""One registry per extension point, one way to add to it (habitat-lab's registry, Gymnasium's entry points).

Kinds (:data:`KINDS`): ``stage``, ``avoidance``, ``llm``, ``motion_generator``, ``policy``, ``sensor``,
``metric``, ``render_backend``, ``camera_model``. Built-ins register themselves exactly as a third
party does::

    from song.plugins import register

    @register("avoidance", "keep_right")
    class KeepRight:
        def __init__(self, mesh, cfg): ...

Everything that names a plugin (a config value such as ``crowd.avoidance``, ``song eval --policy``, a
policy's ``sensors``) accepts a registered name, ``package.module:Attr`` or ``path/to/file.py:Attr``.

Third-party packages are discovered through the entry-point group ``song.plugins``: each entry point
names a module (or ``module:attr``) whose import registers its plugins. Entry points are loaded in
every process (workers too) the first time a kind's names are listed or a name is not found, so a
plugin installed with ``pip`` is found by name in ``-j 2`` runs without any import in user code.

This module sits below every layer: it imports no other part of ``song`` but the error tree, and a
kind's built-ins are registered by the module that owns the kind (imported before it looks names up).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, TypeVar

from song.errors import SongError

ENTRY_POINT_GROUP = "song.plugins"
KINDS = {
    "stage": "a per-scene pipeline stage (song synth)",
    "avoidance": "a crowd local-avoidance model (crowd.avoidance)",
    "llm": "an LLM provider for intents (intents.llm)",
    "motion_generator": "a full-body motion generator (motion.generator)",
    "policy": "a robot policy (song eval --policy)",
    "sensor": "a robot sensor (a policy's sensors, song eval --sensors)",
    "metric": "an aggregate episode metric (every song eval results table)",
    "render_backend": "a Gaussian render backend (--render-backend)",
    "camera_model": "what a robot camera does to the ideal image (--camera-model)",
}
T = TypeVar("T")

_REGISTRY: dict[str, dict[str, Any]] = {kind: {} for kind in KINDS}
_LOADED_ENTRY_POINTS: set[str] = set()


class PluginError(SongError):
    """A plugin name that nothing registers, or a plugin that cannot be loaded."""


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise PluginError(f"unknown plugin kind '{kind}'; kinds: {', '.join(KINDS)}")


def add(kind: str, name: str, obj: T) -> T:
    """Register ``obj`` as the ``kind`` plugin ``name`` (a later registration of the name replaces it)."""
    _check_kind(kind)
    if not isinstance(name, str) or not name or ":" in name:
        raise PluginError(f"{kind} plugin name {name!r}: expected a non-empty name without ':'")
    _REGISTRY[kind][name] = obj
    return obj


def register(kind: str, name: str | None = None) -> Callable[[T], T]:
    """Decorator form of :func:`add`; ``name`` defaults to the object's ``name`` attribute or ``__name__``."""

    def decorate(obj: T) -> T:
        return add(kind, name or getattr(obj, "name", None) or obj.__name__, obj)

    return decorate


def load_entry_points() -> list[str]:
    """Import every ``song.plugins`` entry point not imported yet in this process; their names."""
    loaded = []
    for point in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda p: p.name):
        key = f"{point.name}={point.value}"
        if key in _LOADED_ENTRY_POINTS:
            continue
        _LOADED_ENTRY_POINTS.add(key)
        try:
            point.load()
        except Exception as exc:  # a broken third-party plugin names itself, once, in one line
            raise PluginError(
                f"entry point '{point.name}' ({point.value}) of group {ENTRY_POINT_GROUP}: {exc}"
            ) from exc
        loaded.append(point.name)
    return loaded


def registered(kind: str) -> dict[str, Any]:
    """Every ``kind`` plugin by name (entry points loaded first), in registration order."""
    _check_kind(kind)
    load_entry_points()
    return dict(_REGISTRY[kind])


def names(kind: str) -> list[str]:
    """The registered names of ``kind``."""
    return list(registered(kind))


def _module_of(spec: str) -> Any:
    """Import ``spec``: a dotted module name, or a ``.py`` file (loaded once, under a name of its own)."""
    if not spec.endswith(".py"):
        return importlib.import_module(spec)
    path = Path(spec).expanduser().resolve()
    if not path.is_file():
        raise FileNotFoundError(path)
    module_name = f"song_plugin_{path.stem}_{abs(hash(str(path))):x}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    module_spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[module_name] = module  # before exec: a module that registers itself is found again
    try:
        module_spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[module_name]
        raise
    return module


def load_spec(kind: str, spec: str) -> Any:
    """The object ``module:Attr`` or ``path/to/file.py:Attr`` names (registered under ``spec`` too)."""
    module_name, _, attr = spec.rpartition(":")
    try:
        module = _module_of(module_name)
    except ModuleNotFoundError as exc:
        raise PluginError(
            f"cannot load {kind} '{spec}': no module named '{exc.name}' (add its folder to PYTHONPATH, "
            "or give the file: path/to/file.py:Attr)"
        ) from exc
    except FileNotFoundError as exc:
        raise PluginError(f"cannot load {kind} '{spec}': no such {kind} file {module_name}") from exc
    except SyntaxError as exc:
        raise PluginError(f"cannot load {kind} '{spec}': {exc.filename}:{exc.lineno}: {exc.msg}") from exc
    except Exception as exc:  # the module itself failed to import
        raise PluginError(f"cannot load {kind} '{spec}': {type(exc).__name__}: {exc}") from exc
    try:
        obj = getattr(module, attr)
    except AttributeError:
        raise PluginError(f"cannot load {kind} '{spec}': {module_name} has no attribute '{attr}'") from None
    _REGISTRY[kind][spec] = obj
    return obj


def lookup(kind: str, name: str) -> Any:
    """The ``kind`` plugin called ``name`` (a registered name, ``module:Attr`` or ``file.py:Attr``).

    Raises:
        PluginError: nothing of that name; the message lists the known names.
    """
    _check_kind(kind)
    if name in _REGISTRY[kind]:
        return _REGISTRY[kind][name]
    if isinstance(name, str) and ":" in name:
        return load_spec(kind, name)
    load_entry_points()
    if name in _REGISTRY[kind]:
        return _REGISTRY[kind][name]
    known = ", ".join(_REGISTRY[kind]) or "none"
    raise PluginError(
        f"unknown {kind.replace('_', ' ')} '{name}'; known: {known} (or module:Attr, path/to/file.py:Attr)"
    )


def check_name(kind: str, name: str, extra: tuple[str, ...] = ()) -> None:
    """Refuse (one line, with the known names) a ``kind`` name that neither ``extra`` nor a plugin answers."""
    if name in extra:
        return
    try:
        lookup(kind, name)
    except PluginError as exc:
        if extra and "known:" in str(exc):
            raise PluginError(str(exc).replace("known: ", f"known: {', '.join(extra)}, ", 1)) from None
        raise
