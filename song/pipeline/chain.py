"""Stage registry, per-scene stage cache (content hashes) and the run loop.

A *stage* turns a scene's earlier artifacts into new files under ``RUN/scenes/<scene_id>/``. Each
scene keeps a ``stages.json`` recording, per stage, the input hash (package files + earlier stages'
outputs + every config value the stage reads + run seed + code version), the sha256 of every output
file, the stage's totals (pedestrians, frames) and the status. A stage whose recorded input hash
matches and whose outputs are intact is skipped, which makes a killed run resumable. A scene that
raises fails alone.

Stages declare what they read: ``depends`` (earlier stages whose outputs are inputs) and ``reads``
(config sections such as ``"crowd"`` or single fields such as ``"crowd.agent_radius_m"``); the cache
key hashes all of them, so a changed value re-runs every stage that read it. The order in which
stages run is derived from ``depends`` (a topological order, ties by name). Stage modules register
themselves with :func:`register_stage` when imported; :func:`load_stages` imports them.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import os
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

import song
from song import plugins
from song.config import SongConfig, config_hash, config_value
from song.datasets.run import RunFolder, RunInfo, read_run_info, write_run_info
from song.datasets.run.integrity import outputs_digest, stage_settings
from song.datasets.scenes import ScenePackage, find_scene_packages, load_scene_package
from song.errors import ConfigError, SongError, StageError
from song.parallel import ExecutorName, parallel_map
from song.util import (
    derive_rng,
    folder_lock,
    read_json_object,
    remove_abandoned_writes,
    sha256_file,
    sha256_json,
    write_json_atomic,
)

# Modules whose import registers the built-in stages (their order is derived from ``depends``).
STAGE_MODULES = (
    "song.pipeline.intents",
    "song.pipeline.crowd",
    "song.pipeline.motion",
    "song.pipeline.binding",
)
PLUGINS_ENV = "SONG_STAGE_PLUGINS"

Status = Literal["ok", "skipped", "failed"]


def stage_rng(config: SongConfig, scene_id: str, stage: str, *item: object) -> np.random.Generator:
    """The generator stage ``stage`` draws ``item`` from for scene ``scene_id`` (:meth:`StageContext.rng`).

    A function of (run seed, scene id, stage, *item) alone: independent of order and workers, and
    askable from another stage (the crowd asks for the body the motion and binding stages will draw).
    """
    return derive_rng(config.seed, scene_id, stage, *item)


@dataclass
class StageContext:
    """What a stage sees for one scene.

    Attributes:
        scene: the validated scene package.
        scene_dir: ``RUN/scenes/<scene_id>/``; the stage writes its outputs here (atomically).
        run_dir: the run folder.
        config: the run configuration.
        stage: this stage's name.
    """

    scene: ScenePackage
    scene_dir: Path
    run_dir: Path
    config: SongConfig
    stage: str

    @property
    def scene_id(self) -> str:
        """The scene's id."""
        return self.scene.scene_id

    def rng(self, *item: object) -> np.random.Generator:
        """Generator seeded by (run seed, scene id, stage, *item): independent of order and workers."""
        return stage_rng(self.config, self.scene_id, self.stage, *item)


@dataclass(frozen=True)
class StageOutput:
    """What a stage wrote: files relative to the scene folder, and counts for the run summary."""

    files: list[str]
    totals: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Stage:
    """A registered per-scene stage.

    Attributes:
        name: short name (``"crowd"``), also the CLI command and the ``stages.json`` key.
        run: writes the stage's outputs into ``ctx.scene_dir``; returns a :class:`StageOutput` (or the
            list of files it wrote, relative to the scene folder).
        depends: names of earlier stages whose outputs are this stage's inputs.
        reads: the config it reads: section names (``"crowd"``) or dotted fields
            (``"crowd.agent_radius_m"``); all are part of the input hash.
    """

    name: str
    run: Callable[[StageContext], StageOutput | list[str]]
    depends: tuple[str, ...] = ()
    reads: tuple[str, ...] = ()


def register_stage(stage: Stage) -> Stage:
    """Add (or replace) a stage: the ``stage`` kind of :mod:`song.plugins`."""
    return plugins.add("stage", stage.name, stage)


def stage_order(stages: Iterable[Stage]) -> list[Stage]:
    """A topological order of ``stages`` by ``depends`` (ties by name); dependencies outside the set are ignored.

    Raises:
        StageError: the dependencies form a cycle.
    """
    by_name = {stage.name: stage for stage in stages}
    pending = {name: {d for d in stage.depends if d in by_name} for name, stage in by_name.items()}
    order: list[Stage] = []
    while pending:
        ready = sorted(name for name, deps in pending.items() if not deps)
        if not ready:
            raise StageError(f"stage dependencies form a cycle among: {', '.join(sorted(pending))}")
        name = ready[0]
        order.append(by_name[name])
        del pending[name]
        for deps in pending.values():
            deps.discard(name)
    return order


def load_stages() -> list[Stage]:
    """Import the stage modules and return the registered stages in dependency order.

    Third-party stages come from ``song.plugins`` entry points (see :mod:`song.plugins`) or from modules
    named in the ``SONG_STAGE_PLUGINS`` environment variable (comma-separated module names).
    """
    extra = [name.strip() for name in os.environ.get(PLUGINS_ENV, "").split(",") if name.strip()]
    for module in (*STAGE_MODULES, *extra):
        importlib.import_module(module)
    return stage_order(plugins.registered("stage").values())


@dataclass
class SceneResult:
    """Outcome of one scene: overall status, per-stage statuses and seconds, totals, and the error if any."""

    scene_id: str
    status: Status
    stages: dict[str, Status] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    totals: dict[str, int] = field(default_factory=dict)
    error: str = ""

    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict (the ``--quiet`` event line, and the form results cross process boundaries in)."""
        return {
            "scene_id": self.scene_id,
            "status": self.status,
            "stages": self.stages,
            "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
            "totals": self.totals,
            "error": self.error,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> SceneResult:
        """Inverse of :meth:`to_json`."""
        return cls(**data)


def _outputs_intact(scene_dir: Path, outputs: dict[str, str]) -> bool:
    for rel, digest in outputs.items():
        path = scene_dir / rel
        if not path.is_file() or sha256_file(path) != digest:
            return False
    return True


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """sha256 over the sources that shape stage outputs (not the CLI, pictures, renderer or runtime).

    A change there invalidates recorded stage results, so a resumed run never mixes code versions.
    """
    root = Path(song.__file__).parent
    digest = hashlib.sha256(song.__version__.encode())
    for path in sorted(root.rglob("*.py")):
        if path.relative_to(root).parts[0] in ("cli", "viz", "runtime", "render"):
            continue
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def stage_config(stage: Stage, config: SongConfig) -> dict[str, Any]:
    """The config values a stage declared it reads, keyed by their dotted names."""
    return {key: config_value(config, key) for key in sorted(stage.reads)}


def stage_input_hash(stage: Stage, scene_files: dict[str, str], config: SongConfig, record: dict[str, Any]) -> str:
    """Hash of everything a stage's outputs depend on (``scene_files``: the package's ``content_hash()``).

    The package is hashed once per scene, not once per stage: its PLY alone takes ~56 ms.
    """
    return sha256_json(
        {
            "stage": stage.name,
            "scene": scene_files,
            "depends": {dep: record.get(dep, {}).get("outputs", {}) for dep in stage.depends},
            "config": sha256_json(stage_config(stage, config)),
            "seed": config.seed,
            "code": code_fingerprint(),
        }
    )


def _made_from(stage: Stage, config: SongConfig, record: dict[str, Any], scene_files: dict) -> dict[str, Any]:
    """What a stage record keeps of its inputs, for staleness checks (:mod:`song.datasets.run.integrity`)."""
    return {
        "scene": scene_files,
        "settings": stage_settings(config, stage.reads),
        "depends": {dep: outputs_digest(record.get(dep, {})) for dep in sorted(stage.depends)},
    }


def downstream(stage_name: str) -> list[str]:
    """``stage_name`` and every registered stage made (directly or not) from its outputs, in run order."""
    names = {stage_name}
    for stage in load_stages():
        if names & set(stage.depends):
            names.add(stage.name)
    return [stage.name for stage in load_stages() if stage.name in names]


def _run_stage(stage: Stage, ctx: StageContext) -> StageOutput:
    output = stage.run(ctx)
    return output if isinstance(output, StageOutput) else StageOutput(list(output))


def run_scene(
    scene_root: Path, run_dir: Path, config: SongConfig, stage_names: Iterable[str] | None = None
) -> SceneResult:
    """Run the registered stages on one scene; never raises for a scene-level problem."""
    stages = load_stages()
    if stage_names is not None:
        wanted = set(stage_names)
        stages = [stage for stage in stages if stage.name in wanted]
    try:
        scene = load_scene_package(scene_root, config.scenes.min_free_area_m2)
    except SongError as exc:
        return SceneResult(scene_id=scene_root.name, status="failed", error=str(exc))
    folder = RunFolder(run_dir).scene(scene.scene_id)
    folder.root.mkdir(parents=True, exist_ok=True)
    remove_abandoned_writes(folder.root)  # a run killed mid-write (kill -9) left a temporary file here
    record = read_json_object(folder.stages)
    scene_files = scene.content_hash()  # what the stages read (checked again by export-bench)
    result = SceneResult(scene_id=scene.scene_id, status="skipped")
    for stage in stages:
        input_hash = stage_input_hash(stage, scene_files, config, record)
        previous = record.get(stage.name, {})
        if (
            previous.get("status") == "ok"
            and previous.get("input_hash") == input_hash
            and _outputs_intact(folder.root, previous.get("outputs", {}))
        ):
            result.stages[stage.name] = "skipped"
            result.totals.update(previous.get("totals", {}))
            made_from = _made_from(stage, config, record, scene_files)
            if any(previous.get(key) != value for key, value in made_from.items()):  # a run from an older song
                previous.update(made_from)  # the input hash matched, so these are what it was made from
                write_json_atomic(folder.stages, record)
            continue
        ctx = StageContext(scene=scene, scene_dir=folder.root, run_dir=run_dir, config=config, stage=stage.name)
        start = time.perf_counter()
        try:
            output = _run_stage(stage, ctx)
        except Exception as exc:  # a bad scene fails alone
            seconds = time.perf_counter() - start
            message = str(exc) if isinstance(exc, SongError) else f"{type(exc).__name__}: {exc}"
            record[stage.name] = {
                "status": "failed",
                "input_hash": input_hash,
                "error": message,
                "traceback": "" if isinstance(exc, SongError) else traceback.format_exc(limit=8),
            }
            write_json_atomic(folder.stages, record)
            result.stages[stage.name] = "failed"
            result.seconds[stage.name] = seconds
            result.status = "failed"
            result.error = f"{stage.name}: {message}"
            return result
        seconds = time.perf_counter() - start
        outputs = {rel: sha256_file(folder.path(rel)) for rel in sorted(output.files)}
        # Timings are kept out of stages.json so that run folders are byte-identical across runs.
        record[stage.name] = {"status": "ok", "input_hash": input_hash, "outputs": outputs}
        record[stage.name].update(_made_from(stage, config, record, scene_files))
        if output.totals:
            record[stage.name]["totals"] = dict(sorted(output.totals.items()))
        write_json_atomic(folder.stages, record)
        result.stages[stage.name] = "ok"
        result.seconds[stage.name] = seconds
        result.totals.update(output.totals)
        result.status = "ok"
    return result


def _run_scene_job(args: tuple[str, str, str, tuple[str, ...] | None]) -> dict[str, Any]:
    scene_root, run_dir, config_json, names = args
    config = SongConfig.model_validate_json(config_json)
    return run_scene(Path(scene_root), Path(run_dir), config, names).to_json()


def iter_run(
    scenes_dir: str | Path,
    run_dir: str | Path,
    config: SongConfig,
    stage_names: Iterable[str] | None = None,
    workers: int = 1,
    executor: ExecutorName = "process",
    scheduler: str | None = None,
    scene_ids: Iterable[str] | None = None,
) -> Iterator[SceneResult]:
    """Run the chain over every scene package in ``scenes_dir``, yielding results as scenes finish.

    A scene is the unit of work, mapped by :func:`song.parallel.parallel_map` (``serial``, a local
    ``process`` pool of ``workers``, or ``dask`` at ``scheduler``). Outputs do not depend on the
    executor, the worker count or the completion order.
    """
    check_plugin_names(config)  # an unknown name fails here, before anything is written
    run = RunFolder(Path(run_dir))
    _refuse_foreign_folder(run)
    run.root.mkdir(parents=True, exist_ok=True)
    roots = find_scene_packages(scenes_dir)
    if scene_ids is not None:
        wanted = set(scene_ids)
        roots = [root for root in roots if root.name in wanted]
    known = {stage.name for stage in load_stages()}
    unknown = sorted(set(stage_names or ()) - known)
    if unknown:
        raise StageError(f"unknown stage '{unknown[0]}'; registered: {', '.join(sorted(known))}")
    with folder_lock(run.lock_file, "run folder"):
        write_run_info(run, RunInfo(Path(scenes_dir).resolve(), config, config_hash(config), song.__version__))
        names = tuple(stage_names) if stage_names is not None else None
        jobs = [(str(root), str(run.root), config.model_dump_json(), names) for root in roots]
        for data in parallel_map(_run_scene_job, jobs, workers, executor, scheduler):
            yield SceneResult.from_json(data)


def check_plugin_names(config: SongConfig) -> None:
    """Refuse (one line, listing the known names) a config naming a plugin that nothing registers.

    Raises:
        ConfigError: ``intents.llm``, ``crowd.avoidance`` or ``motion.generator`` names no plugin.
    """
    load_stages()  # the stage modules register their kinds' built-ins
    checks = (
        ("intents.llm", "llm", config.intents.llm, ("auto", "offline")),
        ("crowd.avoidance", "avoidance", config.crowd.avoidance, ()),
        ("motion.generator", "motion_generator", config.motion.generator, ("auto",)),
    )
    for key, kind, name, extra in checks:
        try:
            plugins.check_name(kind, name, extra)
        except plugins.PluginError as exc:
            raise ConfigError("<config>", key, str(exc)) from None


def _refuse_foreign_folder(run: RunFolder) -> None:
    """Refuse a non-empty folder that is not a run (its files are someone else's), or a broken run.json.

    Raises:
        StageError: one line naming the folder or its run.json.
    """
    if not run.root.is_dir() or not any(run.root.iterdir()):
        return
    if not run.info_file.is_file():
        raise StageError(f"{run.root}: not empty and not a song run (no run.json); choose another --out")
    read_run_info(run.root)  # a run.json that is not a run's is refused with its own one line


def read_run(run_dir: str | Path) -> tuple[Path, SongConfig]:
    """The scenes folder and configuration recorded in ``RUN/run.json`` by :func:`iter_run`."""
    info = read_run_info(run_dir)
    return info.scenes_dir, info.config


@dataclass(frozen=True)
class RunSummary:
    """Totals of a chain run over its scenes (what ``song synth`` prints)."""

    scenes: dict[str, int]
    stage_seconds: dict[str, float]
    totals: dict[str, int]
    failed: list[tuple[str, str]]


def summarize_run(results: list[SceneResult], stage_names: list[str]) -> RunSummary:
    """Counts by status, CPU seconds per stage, summed totals and the failures (by scene id)."""
    results = sorted(results, key=lambda r: r.scene_id)
    totals: dict[str, int] = {}
    for result in results:
        if result.status != "failed":
            for key, value in result.totals.items():
                totals[key] = totals.get(key, 0) + int(value)
    return RunSummary(
        scenes={status: sum(r.status == status for r in results) for status in ("ok", "skipped", "failed")},
        stage_seconds={name: sum(r.seconds.get(name, 0.0) for r in results) for name in stage_names},
        totals=totals,
        failed=[(r.scene_id, r.error) for r in results if r.status == "failed"],
    )
