"""Does a run still match its inputs? Each stage records what it was made from.

``stages.json`` keeps, per completed stage:

- ``"scene"``: ``{file name: sha256}`` of the package files it read;
- ``"settings"``: the config values it read (``{"crowd.agent_radius_m": 0.25, "seed": 0, …}``);
- ``"depends"``: ``{upstream stage: sha256 of that stage's recorded outputs}`` when it ran.

A stage is **stale** when any of these no longer holds: an upstream stage re-ran (its outputs changed),
is stale itself or did not complete, or the run's settings (``run.json``) now say otherwise. The grade
records a digest of every scene's completed stages (:func:`graded_inputs`), so a scene re-synthesised
after grading makes the episodes stale too. ``song grade`` and ``song export-bench`` refuse stale
inputs with one line saying what to run; nothing downstream of a changed stage is ever used silently.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from song.config import SongConfig, config_value
from song.datasets.run.layout import SceneFolder
from song.datasets.scenes.package import PACKAGE_FILES
from song.errors import StageError
from song.util import read_json_object, sha256_file, sha256_json

SEED_KEY = "seed"  # the run seed, recorded with a stage's settings


def stage_settings(config: SongConfig, reads: tuple[str, ...] | list[str]) -> dict[str, Any]:
    """The config values a stage reads (dotted keys, JSON values) and the run seed: what made its outputs."""
    return {**{key: config_value(config, key) for key in sorted(reads)}, SEED_KEY: config.seed}


def outputs_digest(entry: dict[str, Any]) -> str:
    """sha256 of a stage record's outputs (file → sha256): what a downstream stage records having read."""
    return sha256_json(entry.get("outputs", {}))


def _completed(record: dict[str, Any], name: str) -> bool:
    entry = record.get(name)
    return isinstance(entry, dict) and entry.get("status") == "ok"


def _setting_now(config: SongConfig, key: str) -> Any:
    if key == SEED_KEY:
        return config.seed
    try:
        return json.loads(json.dumps(config_value(config, key)))  # tuples as lists, as the record has them
    except Exception:  # a setting this version no longer has
        return "<no such setting>"


def _first_difference(key: str, old: Any, new: Any) -> tuple[str, Any, Any]:
    """The first leaf (dotted key, old, new) where two recorded config values differ."""
    if isinstance(old, dict) and isinstance(new, dict):
        for part in sorted(set(old) | set(new)):
            if old.get(part) != new.get(part):
                return _first_difference(f"{key}.{part}", old.get(part), new.get(part))
    return key, old, new


def stale_stages(folder: SceneFolder, config: SongConfig) -> dict[str, str]:
    """``{stage: why}`` for every completed stage of a scene whose inputs no longer match (see the module)."""
    record = read_json_object(folder.stages)
    stale: dict[str, str] = {}
    seen: set[str] = set()

    def visit(name: str) -> None:
        if name in seen:
            return
        seen.add(name)
        entry = record[name]
        depends = entry.get("depends")
        settings = entry.get("settings")
        if not isinstance(depends, dict) or not isinstance(settings, dict):
            stale[name] = "it records no settings or upstream digests (made by an older song)"
            return
        for dep, digest in sorted(depends.items()):
            if not _completed(record, dep):
                stale[name] = f"the '{dep}' stage it was made from did not complete"
                return
            visit(dep)
            if dep in stale:
                stale[name] = f"the '{dep}' stage it was made from is stale"
                return
            if outputs_digest(record[dep]) != digest:
                stale[name] = f"the '{dep}' stage re-ran after it"
                return
        for key, value in sorted(settings.items()):
            now = _setting_now(config, key)
            if now != value:
                key, value, now = _first_difference(key, value, now)
                stale[name] = f"made with {key}={json.dumps(value)}, the run's settings say {json.dumps(now)}"
                return

    for name in sorted(record):
        if _completed(record, name):
            visit(name)
    return stale


def check_fresh(folder: SceneFolder, config: SongConfig, fix: str) -> None:
    """Refuse (one line) when any completed stage of the scene is stale; ``fix`` says what to run.

    Raises:
        StageError: naming the scene's ``stages.json``, the stage and why it is stale.
    """
    stale = stale_stages(folder, config)
    if stale:
        name = next(iter(sorted(stale)))
        raise StageError(f"{folder.stages}: the '{name}' stage is stale ({stale[name]}); {fix}")


def graded_inputs(folder: SceneFolder) -> str:
    """sha256 of a scene's completed stages (their outputs and the scene files they read): what a grade used."""
    record = read_json_object(folder.stages)
    done = {name: {"outputs": e.get("outputs", {}), "scene": e.get("scene", {})} for name, e in record.items()
            if _completed(record, name)}  # fmt: skip
    return sha256_json(done)


def check_scene_unchanged(folder: SceneFolder, package_root: Path) -> None:
    """Refuse (one line naming the scene file) when a package file differs from what the stages read.

    Raises:
        StageError: a recorded file changed, vanished or appeared, or no completed stage recorded its
            inputs (a run from an older song: re-run ``song synth``, it resumes).
    """
    record = read_json_object(folder.stages)
    completed = {name: entry for name, entry in sorted(record.items()) if _completed(record, name)}
    if not completed:
        raise StageError(f"{folder.stages}: no completed stage for scene '{folder.scene_id}'; run `song synth` first")
    present = {name: package_root / name for name in PACKAGE_FILES if (package_root / name).is_file()}
    digests: dict[str, str] = {}  # each file hashed once, whatever the number of stages that read it
    for stage, entry in completed.items():
        files = entry.get("scene")
        if not isinstance(files, dict):
            raise StageError(
                f"{folder.stages}: stage '{stage}' recorded no scene hashes (an older run); re-run `song synth`"
            )
        for name in sorted(set(files) | set(present)):
            if name in present and name not in digests:
                digests[name] = sha256_file(present[name])
            now = digests.get(name)
            if now != files.get(name):
                change = "appeared" if name not in files else "was removed" if now is None else "changed"
                raise StageError(
                    f"{package_root / name}: {change} since the '{stage}' stage read the scene; "
                    "re-run `song synth` (it resumes) and `song grade` before exporting"
                )
