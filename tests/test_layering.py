"""DESIGN §2 dependency rule, checked by parsing every module's imports with ``ast``.

Imports made through strings (``importlib.import_module("song.pipeline.intents")``, registries of
module names such as the chain's ``STAGE_MODULES`` or the CLI's ``COMMAND_MODULES``, entry points
written ``"song.runtime.env:SongNavEnv"``) count too: every string constant that names a song module
is treated as an import.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "song"
BASE = {"song", "song.errors", "song.util", "song.config", "song.parallel", "song.plugins"}
# layer -> song packages it may import (besides itself and BASE)
ALLOWED = {
    "song.geometry": set(),
    "song.render": {"song.geometry"},
    "song.datasets": {"song.geometry"},
    "song.pipeline": {"song.geometry", "song.datasets"},
    "song.runtime": {"song.geometry", "song.datasets", "song.render"},
    "song.viz": {"song.geometry", "song.datasets", "song.pipeline", "song.runtime", "song.render"},
    "song.cli": {"song.geometry", "song.datasets", "song.pipeline", "song.runtime", "song.viz", "song.render"},
}
STAGE_ORDER = ["intents", "crowd", "motion", "binding", "grading"]


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULE_STRING = re.compile(r"^(song(?:\.[A-Za-z_][A-Za-z0-9_]*)+)(?::[A-Za-z_][A-Za-z0-9_.]*)?$")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            match = MODULE_STRING.match(node.value.strip())
            if (
                match
                and (ROOT.parent / match.group(1).replace(".", "/")).with_suffix(".py").exists()
                or (match and (ROOT.parent / match.group(1).replace(".", "/") / "__init__.py").exists())
            ):
                found.add(match.group(1))  # a module imported by name (importlib, registries, entry points)
    return {name for name in found if name == "song" or name.startswith("song.")}


def _layer(module: str) -> str | None:
    if module == "song.__main__":
        return "song.cli"
    for layer in ALLOWED:
        if module == layer or module.startswith(layer + "."):
            return layer
    return None


MODULES = sorted(ROOT.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT.parent)))
def test_module_respects_layers(path: Path) -> None:
    module = _module_name(path)
    layer = _layer(module)
    for imported in _imports(path):
        if imported in BASE or _layer(imported) == layer:
            continue
        if layer is None:  # bottom modules (errors, util, config) import only each other
            assert imported in BASE, f"{module} imports {imported}"
            continue
        assert _layer(imported) in ALLOWED[layer], f"{module} ({layer}) must not import {imported}"
    if module.startswith("song.geometry"):
        assert not {i for i in _imports(path) if not i.startswith("song.geometry")}, module


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(ROOT.parent)))
def test_stage_never_imports_later_stage(path: Path) -> None:
    module = _module_name(path)
    parts = module.split(".")
    if len(parts) < 3 or parts[1] != "pipeline" or parts[2] not in STAGE_ORDER:
        return
    own = STAGE_ORDER.index(parts[2])
    for imported in _imports(path):
        iparts = imported.split(".")
        if len(iparts) >= 3 and iparts[1] == "pipeline" and iparts[2] in STAGE_ORDER:
            assert STAGE_ORDER.index(iparts[2]) <= own, f"{module} imports later stage {imported}"


def test_runtime_never_imports_pipeline() -> None:
    for path in (ROOT / "runtime").rglob("*.py"):
        assert not any(i.startswith("song.pipeline") for i in _imports(path)), path


def test_rule_catches_a_violation(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("from song.pipeline.chain import run_scene\n")
    assert _imports(bad) == {"song.pipeline.chain"}
    assert _layer("song.pipeline.chain") not in ALLOWED["song.runtime"]


def test_rule_catches_imports_by_name(tmp_path: Path) -> None:
    sneaky = tmp_path / "sneaky.py"
    sneaky.write_text(
        "import importlib\n"
        "PLUGINS = ('song.pipeline.intents',)\n"
        "chain = importlib.import_module('song.pipeline.chain')\n"
        "ENTRY = 'song.runtime.env:SongNavEnv'\n"
        "TEXT = 'song.not_a_module and prose'\n"
    )
    assert _imports(sneaky) == {"song.pipeline.intents", "song.pipeline.chain", "song.runtime.env"}
    # the registries of the chain and the CLI are seen through their strings
    assert "song.pipeline.binding" in _imports(ROOT / "pipeline" / "chain.py")
    assert "song.cli.eval" in _imports(ROOT / "cli" / "__init__.py")
