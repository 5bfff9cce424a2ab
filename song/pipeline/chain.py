"""Stage registry, per-scene stage cache and executors (DESIGN §2, §3).

A *stage* turns a scene's earlier artifacts into new files under ``RUN/scenes/<scene_id>/``. Each
scene keeps a ``stages.json`` recording, per stage, the input hash (package files + earlier stages'
outputs + the stage's config section + run seed + code version), the sha256 of every output file, the
time taken and the status. A stage whose recorded input hash matches and whose outputs are intact is
skipped, which makes a killed run resumable. A scene that raises fails alone.

Stage modules register themselves with :func:`register_stage` when imported; :func:`load_stages`
imports the known stage modules in pipeline order.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import json
import os
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

import song
from song.config import SongConfig, config_hash
from song.datasets.scenes import ScenePackage, find_scene_packages, load_scene_package
from song.errors import SongError, StageError
from song.util import derive_rng, sha256_file, sha256_json, write_json_atomic

STAGES_FILE = "stages.json"
RUN_FILE = "run.json"
SCENES_DIR = "scenes"
# Stages that `song synth` runs, in pipeline order (each module registers its stage on import).
STAGE_MODULES = (
    "song.pipeline.intents",
    "song.pipeline.crowd",
    "song.pipeline.motion",
    "song.pipeline.binding",
)
PIPELINE_ORDER = ("intents", "crowd", "motion", "binding")

Status = Literal["ok", "skipped", "failed"]


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
        return self.scene.scene_id

    def rng(self, *item: object) -> np.random.Generator:
        """Generator seeded by (run seed, scene id, stage, *item): independent of order and workers."""
        return derive_rng(self.config.seed, self.scene_id, self.stage, *item)


@dataclass(frozen=True)
class Stage:
    """A registered per-scene stage.

    Attributes:
        name: short name (``"crowd"``), also the CLI command and the ``stages.json`` key.
        run: writes the stage's outputs into ``ctx.scene_dir`` and returns their paths relative to it.
        depends: names of earlier stages whose outputs are this stage's inputs.
        config_section: the :class:`SongConfig` field whose hash is part of the input hash.
    """

    name: str
    run: Callable[[StageContext], list[str]]
    depends: tuple[str, ...] = ()
    config_section: str = ""


_REGISTRY: dict[str, Stage] = {}


def register_stage(stage: Stage) -> Stage:
    """Add (or replace) a stage in the registry."""
    _REGISTRY[stage.name] = stage
    return stage


def load_stages() -> list[Stage]:
    """Import the stage modules that exist and return the registered stages in pipeline order.

    Extra stage modules (plugins) can be named in the ``SONG_STAGE_PLUGINS`` environment variable
    (comma-separated module names); they run after the built-in stages.
    """
    plugins = tuple(name for name in os.environ.get("SONG_STAGE_PLUGINS", "").split(",") if name.strip())
    for module in plugins:
        importlib.import_module(module.strip())
    for module in STAGE_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
    order = {name: index for index, name in enumerate(PIPELINE_ORDER)}
    return sorted(_REGISTRY.values(), key=lambda stage: order.get(stage.name, len(order)))


@dataclass
class SceneResult:
    """Outcome of one scene: overall status, per-stage statuses and seconds, and the error if any."""

    scene_id: str
    status: Status
    stages: dict[str, Status] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    error: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "scene_id": self.scene_id,
            "status": self.status,
            "stages": self.stages,
            "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
            "error": self.error,
        }


def read_stages_file(scene_dir: Path) -> dict[str, Any]:
    """The scene's ``stages.json`` as a dict (empty when missing or unreadable)."""
    path = scene_dir / STAGES_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _outputs_intact(scene_dir: Path, outputs: dict[str, str]) -> bool:
    for rel, digest in outputs.items():
        path = scene_dir / rel
        if not path.is_file() or sha256_file(path) != digest:
            return False
    return True


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """sha256 over the sources that shape stage outputs (not the CLI, pictures or runtime).

    A change there invalidates recorded stage results, so a resumed run never mixes code versions.
    """
    root = Path(song.__file__).parent
    digest = hashlib.sha256(song.__version__.encode())
    for path in sorted(root.rglob("*.py")):
        if path.relative_to(root).parts[0] in ("cli", "viz", "runtime"):
            continue
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def stage_input_hash(stage: Stage, scene: ScenePackage, config: SongConfig, record: dict[str, Any]) -> str:
    """Hash of everything a stage's outputs depend on."""
    section = getattr(config, stage.config_section) if stage.config_section else None
    return sha256_json(
        {
            "stage": stage.name,
            "scene": scene.content_hash(),
            "depends": {dep: record.get(dep, {}).get("outputs", {}) for dep in stage.depends},
            "config": config_hash(section) if section is not None else "",
            "seed": config.seed,
            "code": code_fingerprint(),
        }
    )


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
    scene_dir = run_dir / SCENES_DIR / scene.scene_id
    scene_dir.mkdir(parents=True, exist_ok=True)
    record = read_stages_file(scene_dir)
    result = SceneResult(scene_id=scene.scene_id, status="skipped")
    for stage in stages:
        input_hash = stage_input_hash(stage, scene, config, record)
        previous = record.get(stage.name, {})
        if (
            previous.get("status") == "ok"
            and previous.get("input_hash") == input_hash
            and _outputs_intact(scene_dir, previous.get("outputs", {}))
        ):
            result.stages[stage.name] = "skipped"
            continue
        ctx = StageContext(scene=scene, scene_dir=scene_dir, run_dir=run_dir, config=config, stage=stage.name)
        start = time.perf_counter()
        try:
            written = stage.run(ctx)
        except Exception as exc:  # a bad scene fails alone (DESIGN §3)
            seconds = time.perf_counter() - start
            message = str(exc) if isinstance(exc, SongError) else f"{type(exc).__name__}: {exc}"
            record[stage.name] = {
                "status": "failed",
                "input_hash": input_hash,
                "error": message,
                "traceback": "" if isinstance(exc, SongError) else traceback.format_exc(limit=8),
            }
            write_json_atomic(scene_dir / STAGES_FILE, record)
            result.stages[stage.name] = "failed"
            result.seconds[stage.name] = seconds
            result.status = "failed"
            result.error = f"{stage.name}: {message}"
            return result
        seconds = time.perf_counter() - start
        outputs = {rel: sha256_file(scene_dir / rel) for rel in sorted(written)}
        # Timings are kept out of stages.json so that run folders are byte-identical across runs.
        record[stage.name] = {"status": "ok", "input_hash": input_hash, "outputs": outputs}
        write_json_atomic(scene_dir / STAGES_FILE, record)
        result.stages[stage.name] = "ok"
        result.seconds[stage.name] = seconds
        result.status = "ok"
    return result


def _run_scene_job(args: tuple[str, str, str, tuple[str, ...] | None]) -> dict[str, Any]:
    scene_root, run_dir, config_json, names = args
    config = SongConfig.model_validate_json(config_json)
    return run_scene(Path(scene_root), Path(run_dir), config, names).to_json()


ExecutorName = Literal["serial", "process", "dask"]


def _map_serial(jobs: list[tuple], workers: int, scheduler: str | None) -> Iterator[dict[str, Any]]:
    for job in jobs:
        yield _run_scene_job(job)


def _map_process(jobs: list[tuple], workers: int, scheduler: str | None) -> Iterator[dict[str, Any]]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn, not fork: workers start clean (no inherited torch/OpenMP state or open handles).
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [pool.submit(_run_scene_job, job) for job in jobs]
        for future in as_completed(futures):
            yield future.result()


def _map_dask(jobs: list[tuple], workers: int, scheduler: str | None) -> Iterator[dict[str, Any]]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        from song.errors import MissingDependencyError

        raise MissingDependencyError("dask.distributed", "dask") from exc
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        futures = [client.submit(_run_scene_job, job, pure=False) for job in jobs]
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


EXECUTORS: dict[str, Callable[[list[tuple], int, str | None], Iterator[dict[str, Any]]]] = {
    "serial": _map_serial,
    "process": _map_process,
    "dask": _map_dask,
}


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

    A scene is the unit of work. ``executor`` is ``serial``, ``process`` (a local pool of
    ``workers`` processes; serial when ``workers`` is 1) or ``dask`` (``scheduler`` address such as
    ``tcp://host:8786``, or an in-process ``LocalCluster`` of ``workers`` when None). Outputs do not
    depend on the executor, the worker count or the completion order (DESIGN §3).
    """
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    roots = find_scene_packages(scenes_dir)
    if scene_ids is not None:
        wanted = set(scene_ids)
        roots = [root for root in roots if root.name in wanted]
    write_json_atomic(
        run_dir / RUN_FILE,
        {
            "config": config.model_dump(mode="json"),
            "config_sha256": config_hash(config),
            "scenes_dir": str(Path(scenes_dir).resolve()),
            "song": song.__version__,
        },
    )
    names = tuple(stage_names) if stage_names is not None else None
    jobs = [(str(root), str(run_dir), config.model_dump_json(), names) for root in roots]
    if executor not in EXECUTORS:
        raise StageError(f"unknown executor '{executor}'; choose one of {', '.join(EXECUTORS)}")
    if executor == "process" and (workers <= 1 or len(jobs) <= 1):
        executor = "serial"
    for data in EXECUTORS[executor](jobs, workers, scheduler):
        yield _result_from_json(data)


def _result_from_json(data: dict[str, Any]) -> SceneResult:
    return SceneResult(
        scene_id=data["scene_id"],
        status=data["status"],
        stages=data["stages"],
        seconds=data["seconds"],
        error=data["error"],
    )


def read_run(run_dir: str | Path) -> tuple[Path, SongConfig]:
    """The scenes folder and configuration recorded in ``RUN/run.json`` by :func:`iter_run`."""
    path = Path(run_dir) / RUN_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return Path(data["scenes_dir"]), SongConfig.model_validate(data["config"])
    except (OSError, ValueError, KeyError) as exc:
        raise StageError(f"{path}: not a run folder (run.json missing or unreadable): {exc}") from exc


def require_stage(name: str) -> Stage:
    """The registered stage called ``name``; :class:`StageError` listing the known ones otherwise."""
    stages = {stage.name: stage for stage in load_stages()}
    if name not in stages:
        raise StageError(f"unknown stage '{name}'; registered: {', '.join(stages) or 'none'}")
    return stages[name]
