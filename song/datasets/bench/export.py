"""``song export-bench``: a run's graded episodes → one immutable versioned release.

The release is built in a hidden temporary folder beside the target and renamed into place at the
end, so an interrupted export leaves no half version visible; an existing version is never touched.
"""

from __future__ import annotations

import datetime as dt
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import song
from song.datasets.bench.info import SEMVER, Generator, Info, TableInfo, fingerprint_of  # noqa: F401 (re-exported)
from song.datasets.bench.io import BlobStore, write_parquet
from song.datasets.bench.schema import (
    AVATARS,
    AVATARS_PATH,
    CHANGELOG_PATH,
    EPISODES,
    EPISODES_PATH,
    INFO_PATH,
    MANIFEST,
    MANIFEST_PATH,
    PEDESTRIANS,
    PEDESTRIANS_PATH,
    SCENES,
    SCENES_PATH,
)
from song.datasets.run import RunFolder, RunInfo, read_bindings, read_crowd_table, read_intents, read_run_info
from song.datasets.run.integrity import check_fresh, check_scene_unchanged, graded_inputs
from song.datasets.run.layout import AMASS_FILE, MOTION_META_FILE
from song.datasets.scenes.package import GAUSSIANS, SEMANTIC_MAP, USD_PROXY, load_scene_package
from song.errors import BenchmarkError, SongError
from song.util import (
    process_gone,
    read_json_object,
    sha256_file,
    write_json_atomic,
)


@dataclass(frozen=True)
class ExportResult:
    """Where the release went and what it holds."""

    path: Path
    version: str
    fingerprint: str
    n_episodes: int
    n_bytes: int


def yaw_to_quat_xyzw(yaw: np.ndarray) -> np.ndarray:
    """Quaternions [x, y, z, w] of rotations by ``yaw`` (rad) about +z; (N,) → (N, 4)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    return np.stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)], axis=-1)


def _run_inputs(run: RunFolder) -> RunInfo:
    try:
        return read_run_info(run.root)
    except SongError as exc:
        raise BenchmarkError(str(exc)) from exc


def _check_graded_inputs(run: RunFolder, run_info: RunInfo, scene_ids: list[str]) -> None:
    """Refuse stale stages, edited scenes, and episodes graded from other stage outputs than today's.

    Raises:
        StageError: a scene's stage is stale or its package changed (run ``song synth``).
        BenchmarkError: a scene's stages re-ran after the grade (run ``song grade``).
    """
    graded = read_json_object(run.grading_summary).get("inputs", {})
    fix = f"run `song synth --scenes {run_info.scenes_dir} --out {run.root}` and `song grade --run {run.root}`"
    for scene_id in scene_ids:
        folder = run.scene(scene_id)
        check_fresh(folder, run_info.config, fix)
        check_scene_unchanged(folder, run_info.scenes_dir / scene_id)
        if not isinstance(graded, dict) or graded.get(scene_id) != graded_inputs(folder):
            raise BenchmarkError(
                f"{run.episodes_manifest}: the episodes of scene '{scene_id}' were graded from other stage "
                f"outputs than the run has now; run `song grade --run {run.root}` again"
            )


def _episode_table(run: RunFolder, config_sha: str, goal_radius: float) -> pa.Table:
    path = run.episodes_manifest
    if not path.is_file():
        raise BenchmarkError(f"{path}: missing; run `song grade --run {run.root}` first")
    src = pq.read_table(path).to_pydict()
    n = len(src["episode_id"])
    start = np.column_stack([src["start_x"], src["start_y"], np.zeros(n)]) if n else np.zeros((0, 3))
    goal = np.column_stack([src["goal_x"], src["goal_y"], np.zeros(n)]) if n else np.zeros((0, 3))
    columns = {
        "episode_id": src["episode_id"],
        "scene_id": src["scene_id"],
        "difficulty": src["difficulty"],
        "mode": src["mode"],
        "seed": src["seed"],
        "t0": src["t0"],
        "start_position": start.tolist(),
        "start_yaw": src["start_yaw"],
        "start_rotation": yaw_to_quat_xyzw(np.asarray(src["start_yaw"], dtype=np.float64)).tolist(),
        "goal_position": goal.tolist(),
        "goal_radius": [goal_radius] * n,
        "goals": [[{"position": g, "radius": goal_radius}] for g in goal.tolist()],
        "geodesic_distance": src["geodesic_distance"],
        "optimal_time": src["optimal_time"],
        "path": src["path"],
        "path_length": src["path_length"],
        "n_turns": src["n_turns"],
        "n_encounters": src["n_encounters"],
        "corridor_width": src["corridor_width"],
        "bin_length": src["bin_length"],
        "bin_turns": src["bin_turns"],
        "bin_encounters": src["bin_encounters"],
        "bin_width": src["bin_width"],
        "score": src["score"],
        "n_pedestrians": [len(ids) for ids in src["pedestrian_ids"]],
        "pedestrian_ids": src["pedestrian_ids"],
        "config_sha256": [config_sha] * n,
        # manifests graded before these were recorded: all test, no reference pedestrian, no predicted encounter
        "split": src.get("split", ["test"] * n),
        "reference_ped_id": src.get("reference_ped", [-1] * n),
        "encounter_time": src.get("encounter_time", [None] * n),
    }
    return pa.table(columns).cast(EPISODES).sort_by("episode_id")


def _pedestrian_table(run: RunFolder, scene_ids: list[str]) -> pa.Table:
    parts = []
    for scene_id in scene_ids:
        path = run.scene(scene_id).crowd
        if not path.is_file():
            raise BenchmarkError(f"{path}: missing; run `song synth` on this scene")
        table = read_crowd_table(path)
        table = table.append_column("scene_id", pa.array([scene_id] * table.num_rows, pa.string()))
        parts.append(table.select(PEDESTRIANS.names).cast(PEDESTRIANS))
    table = pa.concat_tables(parts) if parts else PEDESTRIANS.empty_table()
    return table.sort_by([("scene_id", "ascending"), ("ped_id", "ascending"), ("frame", "ascending")])


def _ped_ids_by_scene(pedestrians: pa.Table) -> dict[str, list[int]]:
    """Each scene's pedestrian ids, ascending, in one pass over the table.

    (A filter of the whole table per scene made a 500-scene export quadratic: 12 of its 35 s.)
    """
    pairs = pedestrians.select(["scene_id", "ped_id"]).group_by(["scene_id", "ped_id"]).aggregate([])
    out: dict[str, list[int]] = {}
    for scene_id, ped_id in zip(pairs.column("scene_id").to_pylist(), pairs.column("ped_id").to_pylist(), strict=True):
        out.setdefault(scene_id, []).append(ped_id)
    return {scene_id: sorted(ids) for scene_id, ids in out.items()}


def _avatar_rows(
    run: RunFolder, scene_id: str, ped_ids: list[int], blobs: BlobStore, amass: bool
) -> list[dict[str, Any]]:
    scene = run.scene(scene_id)
    intents = read_intents(scene.intents).by_id() if scene.intents.is_file() else {}
    bindings = read_bindings(scene.bindings).by_ped() if scene.bindings.is_file() else {}
    rows = []
    for ped_id in ped_ids:
        binding = bindings.get(ped_id)
        traj = scene.traj_dir(ped_id)
        height = binding.height_m if binding else read_json_object(traj / MOTION_META_FILE).get("height_m")
        rows.append(
            {
                "scene_id": scene_id,
                "ped_id": ped_id,
                "avatar_id": binding.avatar_id if binding else "",
                "activity": intents[ped_id].activity if ped_id in intents else "",
                "height_m": height,
                "cache": blobs.add(scene.path(binding.cache_file)) if binding else None,
                "asset": blobs.add(Path(binding.asset_path)) if binding else None,
                "amass": blobs.add(traj / AMASS_FILE) if amass else None,
                "materialized": blobs.add(scene.path(binding.materialized_file))
                if binding and binding.materialized_file
                else None,
            }
        )
    return rows


def _scene_row(scenes_dir: Path, scene_id: str, blobs: BlobStore) -> dict[str, Any]:
    package = load_scene_package(scenes_dir / scene_id)
    smap = package.semantic_map
    grid = package.occupancy
    return {
        "scene_id": scene_id,
        "source": smap.source,
        "source_sha256": sha256_file(package.root / SEMANTIC_MAP),
        "venue_type": smap.venue_type,
        "navigable_area_m2": float(grid.free.sum()) * grid.resolution**2,
        "licence": smap.licence or "",
        "resolution": grid.resolution,
        "origin": list(grid.origin),
        "semantic_map": blobs.add(package.root / SEMANTIC_MAP),
        "occupancy": blobs.add(package.root / smap.occupancy.path),
        "gaussians": blobs.add(package.root / GAUSSIANS),
        "usd": blobs.add(package.root / USD_PROXY),
    }


def _git_commit() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=Path(song.__file__).parent, capture_output=True, text=True, timeout=5
        )
        return out.stdout.strip() if out.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        return ""


def _remove_abandoned(bench_dir: Path) -> None:
    """Remove hidden temporary folders of exports whose process no longer runs (killed with kill -9)."""
    for tmp in bench_dir.glob(".*.tmp-*") if bench_dir.is_dir() else []:
        pid = tmp.name.rpartition("-")[2]
        if not pid.isdigit() or not tmp.is_dir() or tmp.is_symlink():
            continue
        if process_gone(int(pid)):
            shutil.rmtree(tmp, ignore_errors=True)


def _created() -> str:
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch is not None and not epoch.strip().isdigit():
        raise SongError(f"SOURCE_DATE_EPOCH={epoch!r} is not a whole number of seconds since 1970-01-01")
    moment = dt.datetime.fromtimestamp(int(epoch), dt.UTC) if epoch else dt.datetime.now(dt.UTC)
    return moment.replace(microsecond=0).isoformat().replace("+00:00", "Z")


def manifest_rows(
    release: Path, rows_by_path: dict[str, int], stored: dict[str, dict] | None = None
) -> list[dict[str, Any]]:
    """One row per file of the release except ``meta/info.json`` and the manifest itself, sorted.

    ``stored``: the blobs this export copied (:meth:`BlobStore.stored`), hashed as they were written;
    their digests are reused when the file still has the size written, every other file is hashed.
    """
    stored = stored or {}
    rows = []
    for path in sorted(release.rglob("*")):
        rel = path.relative_to(release).as_posix()
        if not path.is_file() or rel in (INFO_PATH, MANIFEST_PATH):
            continue
        size = path.stat().st_size
        known = stored.get(rel)
        digest = known["sha256"] if known is not None and known["bytes"] == size else sha256_file(path)
        rows.append({"path": rel, "sha256": digest, "bytes": size, "rows": rows_by_path.get(rel)})
    return rows


def _changelog(version: str, parent: str | None, notes: str, counts: dict[str, Any]) -> str:
    lines = [f"# {version}", "", f"- parent: {parent or 'none'}", f"- episodes: {counts['episodes']}"]
    lines += [f"- {name}: {count}" for name, count in counts["difficulty"].items()]
    if notes:
        lines += ["", notes.strip()]
    return "\n".join(lines) + "\n"


def _counts(episodes: pa.Table, n_scenes: int, n_pedestrians: int) -> dict[str, Any]:
    """The release's counts: episodes, scenes, pedestrians, and episodes per difficulty and per mode."""
    difficulty = episodes.column("difficulty").to_pylist()
    mode = episodes.column("mode").to_pylist()
    return {
        "episodes": episodes.num_rows,
        "scenes": n_scenes,
        "pedestrians": n_pedestrians,
        "difficulty": {d: difficulty.count(d) for d in ("easy", "medium", "hard")},
        "mode": {m: mode.count(m) for m in sorted(set(mode))},
    }


def _release_info(
    version: str, parent: str | None, notes: str, run_info: RunInfo, counts: dict, tables: dict, rows_by_path: dict
) -> Info:
    """``meta/info.json`` before its fingerprint: every runtime parameter the run was made with."""
    config = run_info.config
    robot = config.robot
    return Info(
        dataset_version=version,
        parent=parent,
        notes=notes,
        created=_created(),
        generator=Generator(version=song.__version__, git_commit=_git_commit(), config_sha256=run_info.config_sha256),
        fps=config.crowd.fps,
        robot=robot.model_dump(mode="json"),
        camera=config.camera.model_dump(mode="json"),
        collision={
            "radius_m": robot.radius_m,
            "height_m": robot.collision_height_m,
            "volume": robot.collision_volume,
            "eta_col": robot.eta_col,
        },
        pedestrian_radius_m=config.crowd.agent_radius_m,
        crowd={
            "avoidance": config.crowd.avoidance,
            "comfort_distance_m": config.crowd.comfort_distance_m,
            "speed_profile": config.intents.speed_profile,
            "scenario_s": config.intents.scenario_s,
            "max_legs": config.intents.max_legs,
        },
        counts=counts,
        tables={
            name: TableInfo(path=rel, rows=rows_by_path[rel], columns=list(schema.names))
            for name, (rel, _, schema) in tables.items()
        },
        fingerprint="",
    )


def export_bench(
    run_dir: str | Path,
    bench_dir: str | Path,
    version: str,
    parent: str | None = None,
    notes: str = "",
    amass: bool = False,
) -> ExportResult:
    """Write ``bench_dir/version/`` from a graded run; refuses an existing version.

    ``amass`` also ships each pedestrian's AMASS motion file (about 0.5 MB per pedestrian-minute; the
    runtime needs only the avatar assets and compact LBS caches, which are always included).

    Raises:
        BenchmarkError: bad version string, existing version, missing parent, or missing run outputs.
    """
    run_dir, bench_dir = Path(run_dir), Path(bench_dir)
    if not SEMVER.fullmatch(version):
        raise BenchmarkError(f"version '{version}': expected a semantic version X.Y.Z")
    target = bench_dir / version
    if target.exists():
        raise BenchmarkError(f"{target}: version {version} already exists; releases are immutable, pick a new version")
    if parent is not None and not (bench_dir / parent / INFO_PATH).is_file():
        raise BenchmarkError(f"{bench_dir / parent}: parent version {parent} does not exist")
    run = RunFolder(run_dir)
    run_info = _run_inputs(run)
    config = run_info.config
    robot = config.robot
    episodes = _episode_table(run, run_info.config_sha256, robot.goal_radius_m)
    scene_ids = sorted(set(episodes.column("scene_id").to_pylist()))
    _remove_abandoned(bench_dir)
    tmp = bench_dir / f".{version}.tmp-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    try:
        blobs = BlobStore(tmp)
        pedestrians = _pedestrian_table(run, scene_ids)
        avatar_rows, scene_rows = [], []
        ped_ids = _ped_ids_by_scene(pedestrians)
        _check_graded_inputs(run, run_info, scene_ids)
        for scene_id in scene_ids:
            avatar_rows += _avatar_rows(run, scene_id, ped_ids.get(scene_id, []), blobs, amass)
            scene_rows.append(_scene_row(run_info.scenes_dir, scene_id, blobs))
        tables = {
            "episodes": (EPISODES_PATH.format(part=0), episodes, EPISODES),
            "pedestrians": (PEDESTRIANS_PATH.format(part=0), pedestrians, PEDESTRIANS),
            "avatars": (AVATARS_PATH.format(part=0), pa.Table.from_pylist(avatar_rows, AVATARS), AVATARS),
            "scenes": (SCENES_PATH, pa.Table.from_pylist(scene_rows, SCENES), SCENES),
        }
        rows_by_path = {}
        for name, (rel, table, schema) in tables.items():
            rows_by_path[rel] = write_parquet(tmp / rel, table, schema, name, version)
        counts = _counts(episodes, len(scene_ids), len(avatar_rows))
        (tmp / CHANGELOG_PATH).write_text(_changelog(version, parent, notes, counts), encoding="utf-8")
        manifest = manifest_rows(tmp, rows_by_path, blobs.stored())
        write_parquet(tmp / MANIFEST_PATH, pa.Table.from_pylist(manifest, MANIFEST), MANIFEST, "manifest", version)
        info = _release_info(version, parent, notes, run_info, counts, tables, rows_by_path)
        fingerprint = fingerprint_of(manifest, info.model_dump(mode="json"))
        info = info.model_copy(update={"fingerprint": fingerprint})
        write_json_atomic(tmp / INFO_PATH, info.model_dump(mode="json"))
        n_bytes = sum(p.stat().st_size for p in tmp.rglob("*") if p.is_file())
        os.replace(tmp, target)  # atomic on one file system; fails if target appeared meanwhile
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return ExportResult(target, version, fingerprint, episodes.num_rows, n_bytes)
