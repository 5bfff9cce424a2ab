"""Factors, difficulty split and the manifest (paper "Episode generation and grading")."""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from song.config import GradingConfig, SongConfig
from song.datasets.bench.schema import DIFFICULTIES, MODES
from song.datasets.run import RunFolder, read_crowd, read_run_info
from song.datasets.run.integrity import check_fresh, check_scene_unchanged, graded_inputs
from song.datasets.run.layout import CROWD_FILE
from song.datasets.scenes import load_scene_package
from song.geometry.rotations import wrap_angle
from song.parallel import parallel_map
from song.pipeline.grading.sample import Crowd, EpisodeSampler, RobotMap, closest_pass
from song.util import derive_rng, folder_lock, write_bytes_atomic, write_json_atomic

FACTORS = ("path_length", "n_turns", "n_encounters", "corridor_width")
BINS = ("bin_length", "bin_turns", "bin_encounters", "bin_width")


def count_turns(path: np.ndarray, threshold_deg: float) -> int:
    """Vertices of the smoothed path where the heading changes by more than ``threshold_deg``.

    A smoothed (string-pulled) path has one vertex per turn, so each vertex's heading change is one
    turn; changes at or below the threshold do not count.
    """
    d = np.diff(path, axis=0)
    d = d[np.linalg.norm(d, axis=1) > 1e-9]
    if len(d) < 2:
        return 0
    heading = np.arctan2(d[:, 1], d[:, 0])
    change = np.abs(wrap_angle(np.diff(heading)))
    return int(np.count_nonzero(np.degrees(change) > threshold_deg))


def corridor_width(path: np.ndarray, robot: RobotMap, step: float) -> float:
    """Mean distance to obstacles along the path, sampled every ``step`` metres (EDT)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.arange(0.0, arc[-1] + 1e-9, step)
    pts = np.column_stack([np.interp(s, arc, path[:, 0]), np.interp(s, arc, path[:, 1])])
    rc = robot.package.occupancy.to_cell(pts)
    return float(robot.clearance[rc[:, 0], rc[:, 1]].mean())


def tercile_bins(values: np.ndarray, reverse: bool = False) -> np.ndarray:
    """Three bins (0, 1, 2) of ascending values, as equal in size as the ties allow.

    Equal values always share a bin. Among all ways to cut the sorted distinct values into three
    consecutive groups, the cut whose bin sizes are closest to n/3 each (least squares) is chosen;
    equally good cuts prefer non-empty outer bins (the factor keeps its easy and hard ends). A factor
    with one distinct value says nothing: everything goes to the middle bin. Without ties this is the
    plain equal-frequency split (sizes differ by at most one). With ``reverse`` (corridor width:
    narrower is harder) the bins are flipped.
    """
    values = np.asarray(values, dtype=np.float64)
    n = len(values)
    if n == 0:
        return np.zeros(0, dtype=np.int8)
    distinct, group = np.unique(values, return_inverse=True)
    if len(distinct) == 1:
        return np.ones(n, dtype=np.int8)
    cum = np.concatenate([[0], np.cumsum(np.bincount(group))])  # bin edges may only fall between groups
    best_key, cuts = None, (0, 0)
    for i, a in enumerate(cum):
        j = int(np.searchsorted(cum, a + (n - a) / 2))  # the best second cut is nearest to halving the rest
        for jj in {max(i, j - 1), min(max(i, j), len(cum) - 1)}:
            sizes = np.array([a, cum[jj] - a, n - cum[jj]], dtype=np.float64)
            key = (float(((sizes - n / 3) ** 2).sum()), sizes[0] == 0, sizes[2] == 0)
            if best_key is None or key < best_key:
                best_key, cuts = key, (i, jj)
    bins = np.where(group < cuts[0], 0, np.where(group < cuts[1], 1, 2)).astype(np.int8)
    return (2 - bins).astype(np.int8) if reverse else bins


def bin_report(values: np.ndarray, bins: np.ndarray) -> dict:
    """How a factor was binned: episodes per bin and the number of distinct values (for the summary)."""
    return {"occupancy": np.bincount(bins, minlength=3).tolist(), "distinct": int(len(np.unique(values)))}


def split_difficulty(score: np.ndarray, encounters: np.ndarray, length: np.ndarray, ids: list[str], cfg: GradingConfig):
    """Sort by score, then encounters, then length (all descending), then id; first 20 % hard, next 40 % medium."""
    n = len(ids)
    order = sorted(range(n), key=lambda i: (-score[i], -encounters[i], -length[i], ids[i]))
    n_hard = int(round(cfg.hard_fraction * n))
    n_medium = int(round(cfg.medium_fraction * n))
    out = np.empty(n, dtype=object)
    for rank, i in enumerate(order):
        out[i] = "hard" if rank < n_hard else "medium" if rank < n_hard + n_medium else "easy"
    return out


@dataclass
class GradingResult:
    """What ``song grade`` produced."""

    episodes: pa.Table
    summary: dict


EXTRA_DRAWS = 3  # a scene tries at most this many draws per episode of its quota


def _scene_episodes(scene_id: str, scenes_dir: Path, run_dir: Path, config: SongConfig, quota: int):
    cfg = config.grading
    package = load_scene_package(scenes_dir / scene_id)
    tracks = read_crowd(RunFolder(run_dir).scene(scene_id).crowd)
    if len(tracks.ids) == 0:
        return [], {"*": "no pedestrians in this scene"}
    robot = RobotMap.build(package, cfg.robot_radius_m + cfg.path_margin_m)
    crowd = Crowd(tracks.ids, tracks.xy, tracks.fps)
    sampler = EpisodeSampler(robot, crowd, cfg, duration=crowd.duration)
    rows, infeasible = [], {}
    for k in range(EXTRA_DRAWS * quota):  # a draw that finds no episode is made up by a later one
        if len(rows) == quota:
            break
        rng = derive_rng(config.seed, scene_id, "grading", k)
        mode = MODES[int(rng.integers(len(MODES)))]
        draw, reason = sampler.draw(mode, rng)
        if draw is None:
            infeasible[mode] = reason
            mode = "random"
            draw, reason = sampler.draw(mode, rng)
            if draw is None:
                infeasible["random"] = reason
                continue
        path = draw["path"]
        passes = closest_pass(path, crowd, draw["t0"], cfg.robot_speed_mps)
        first = path[1] - path[0]
        rows.append(
            {
                "episode_id": f"{scene_id}-{k:03d}",
                "scene_id": scene_id,
                "mode": mode,
                "seed": int(rng.integers(2**31)),
                "t0": draw["t0"],
                "start_x": float(draw["start"][0]),
                "start_y": float(draw["start"][1]),
                "start_yaw": float(np.arctan2(first[1], first[0])),
                "goal_x": float(draw["goal"][0]),
                "goal_y": float(draw["goal"][1]),
                "path": path.round(4).tolist(),
                "geodesic_distance": round(draw["length"], 4),
                "optimal_time": round(draw["length"] / cfg.robot_speed_mps, 4),
                "path_length": round(draw["length"], 4),
                "n_turns": count_turns(path, cfg.turn_threshold_deg),
                "n_encounters": int(np.count_nonzero(passes <= cfg.encounter_radius_m)),
                "corridor_width": round(corridor_width(path, robot, cfg.width_sample_m), 4),
                "min_pass_m": round(float(passes.min()), 4),
                "reference_ped": draw["reference_ped"],
                "encounter_time": draw["encounter_time"],
                "pedestrian_ids": tracks.ids.astype(int).tolist(),
            }
        )
    return rows, infeasible


def _quotas(scene_ids: list[str], total: int) -> dict[str, int]:
    base, extra = divmod(total, max(1, len(scene_ids)))
    return {sid: base + (1 if i < extra else 0) for i, sid in enumerate(scene_ids)}


def _scene_job(args: tuple[str, str, str, str, int]):
    scene_id, scenes_dir, run_dir, config_json, quota = args
    config = SongConfig.model_validate_json(config_json)
    return scene_id, *_scene_episodes(scene_id, Path(scenes_dir), Path(run_dir), config, quota)


def parse_splits(spec: str) -> dict[str, float]:
    """``"train:val:test=8:1:1"`` → ``{"train": 0.8, "val": 0.1, "test": 0.1}`` (shares of the scenes)."""
    from song.errors import ConfigError

    names, _, weights = spec.partition("=")
    parts, values = [n.strip() for n in names.split(":")], weights.split(":")
    try:
        shares = [float(v) for v in values]
    except ValueError:
        shares = []
    if len(parts) != len(shares) or len(set(parts)) != len(parts) or not all(parts) or min(shares, default=-1) < 0:
        raise ConfigError("--split", spec, "expected names=weights, e.g. train:val:test=8:1:1")
    if "test" not in parts or sum(shares) <= 0:
        raise ConfigError("--split", spec, "needs a 'test' split and a positive total weight")
    total = sum(shares)
    return {name: share / total for name, share in zip(parts, shares, strict=True)}


def scene_split(scene_id: str, splits: dict[str, float]) -> str:
    """The split of a scene: a stable hash of its id placed on the cumulative shares.

    The hash depends on the id only, so adding scenes never moves a scene to another split.
    """
    u = int(hashlib.sha256(scene_id.encode()).hexdigest()[:15], 16) / 16**15
    edge = 0.0
    for name, share in splits.items():
        edge += share
        if u < edge:
            return name
    return next(reversed(splits))


def grade_run(
    run_dir: str | Path,
    config: SongConfig | None = None,
    n_episodes: int | None = None,
    workers: int = 1,
    splits: dict[str, float] | None = None,
    split_episodes: dict[str, int] | None = None,
) -> GradingResult:
    """Sample, measure and grade episodes over every scene of a run; write the manifest.

    Scenes are sampled independently (seeds per scene and episode), optionally in ``workers``
    processes; the manifest does not depend on the worker count. With ``splits`` (shares of the
    scenes by name, see :func:`parse_splits`) whole scenes go to one split each (:func:`scene_split`),
    every split is graded on its own (bins and difficulty within the split), ``test`` gets
    ``n_episodes`` and the others what ``split_episodes`` asks (default ``n_episodes``). Without
    splits every scene is in ``test``.
    """
    run = RunFolder(Path(run_dir))
    with folder_lock(run.lock_file, "run folder"):
        return _grade_run(run, config, n_episodes, workers, splits, split_episodes)


def _grade_run(run: RunFolder, config, n_episodes, workers, splits, split_episodes) -> GradingResult:
    run_info = read_run_info(run.root)
    config = config or run_info.config
    total = n_episodes or config.grading.n_episodes
    splits = splits or {"test": 1.0}
    scene_ids = run.scene_ids(having=CROWD_FILE)
    fix = f"run `song synth --scenes {run_info.scenes_dir} --out {run.root}` first (it resumes)"
    for scene_id in scene_ids:  # never grade a crowd made from other inputs than the run's
        check_fresh(run.scene(scene_id), run_info.config, fix)
        check_scene_unchanged(run.scene(scene_id), run_info.scenes_dir / scene_id)
    by_split = {name: [s for s in scene_ids if scene_split(s, splits) == name] for name in splits}
    rows, infeasible, binning = [], {}, {}
    for name, ids in by_split.items():
        wanted = total if name == "test" else (split_episodes or {}).get(name, total)
        got, why = _sample(ids, run, run_info, config, wanted, workers)
        infeasible.update(why)
        binning[name] = _grade(got, config.grading)
        rows += [{**r, "split": name} for r in got]
    rows.sort(key=lambda r: r["episode_id"])
    table = pa.Table.from_pylist(rows) if rows else pa.table({"episode_id": pa.array([], pa.string())})
    summary = _summary(rows, infeasible, total) | {
        "bins": binning,  # per split, per factor
        "splits": {name: {"scenes": len(ids), "episodes": sum(r["split"] == name for r in rows)}
                   for name, ids in by_split.items()},
        "inputs": {scene_id: graded_inputs(run.scene(scene_id)) for scene_id in scene_ids},
    }  # fmt: skip
    buffer = io.BytesIO()
    pq.write_table(table, buffer, compression="zstd", compression_level=9)
    write_bytes_atomic(run.episodes_manifest, buffer.getvalue())
    write_json_atomic(run.grading_summary, summary)
    return GradingResult(table, summary)


def _sample(scene_ids: list[str], run: RunFolder, run_info, config: SongConfig, total: int, workers: int):
    """Episodes of ``scene_ids`` (``total`` spread over them), sorted by id, and why modes were infeasible."""
    rows, infeasible = [], {}
    quotas = _quotas(scene_ids, total)
    jobs = [(sid, str(run_info.scenes_dir), str(run.root), config.model_dump_json(), quotas[sid]) for sid in scene_ids]
    for scene_id, got, why in parallel_map(_scene_job, jobs, workers):
        rows += got
        if why:
            infeasible[scene_id] = why
    rows.sort(key=lambda r: r["episode_id"])
    return rows, infeasible


def _grade(rows: list[dict], cfg: GradingConfig) -> dict:
    """Bin the factors, score and split ``rows`` by difficulty in place; returns the bin report."""
    ids = [r["episode_id"] for r in rows]
    values = {f: np.array([r[f] for r in rows], dtype=np.float64) for f in FACTORS}
    binning = {}
    for factor, name in zip(FACTORS, BINS, strict=True):
        bins = tercile_bins(values[factor], reverse=factor == "corridor_width")
        binning[factor] = bin_report(values[factor], bins)
        for row, b in zip(rows, bins, strict=True):
            row[name] = int(b)
    score = np.array([sum(r[b] for b in BINS) for r in rows])
    difficulty = split_difficulty(score, values["n_encounters"], values["path_length"], ids, cfg)
    for row, s, d in zip(rows, score, difficulty, strict=True):
        row["score"], row["difficulty"] = int(s), str(d)
    return binning


def _summary(rows: list[dict], infeasible: dict, requested: int) -> dict:
    counts: dict[str, dict[str, int]] = {}
    factors: dict[str, dict[str, dict[str, float]]] = {}
    for difficulty in DIFFICULTIES:
        subset = [r for r in rows if r["difficulty"] == difficulty]
        counts[difficulty] = {mode: sum(r["mode"] == mode for r in subset) for mode in MODES}
        factors[difficulty] = {
            f: {"median": float(np.median([r[f] for r in subset])) if subset else float("nan")} for f in FACTORS
        }
    return {
        "requested": requested,
        "episodes": len(rows),
        "counts": counts,
        "factors": json.loads(json.dumps(factors).replace("NaN", "null")),
        "infeasible": infeasible,
    }
