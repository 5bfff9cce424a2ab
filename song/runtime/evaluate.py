"""``song eval``: run a policy over a release's episodes; per-episode Parquet + summary (DESIGN §8)."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from song.config import RobotConfig
from song.datasets.bench import Benchmark, Episode, open_benchmark
from song.runtime.avatars import AvatarCollider, make_collider
from song.runtime.loop import EpisodeResult, run_episode
from song.runtime.metrics import aggregate, markdown_table
from song.runtime.policies import load_policy
from song.util import write_bytes_atomic, write_json_atomic, write_text_atomic

RESULTS_SCHEMA = pa.schema(
    [
        ("episode_id", pa.string()),
        ("scene_id", pa.string()),
        ("difficulty", pa.string()),
        ("policy", pa.string()),
        ("outcome", pa.string()),
        ("steps", pa.int32()),
        ("time", pa.float64()),
        ("length", pa.float64()),
        ("optimal_length", pa.float64()),
        ("optimal_time", pa.float64()),
        ("obstacle_collisions", pa.int32()),
        ("max_gaussian_count", pa.int32()),
        ("psc", pa.float64()),
        ("min_distance", pa.float64()),
        ("jerk", pa.float64()),
        ("trajectory", pa.list_(pa.list_(pa.float64(), 3))),
        ("events", pa.list_(pa.struct([("step", pa.int32()), ("kind", pa.string())]))),
    ]
)


@dataclass(frozen=True)
class EvalJob:
    bench: str
    episode_id: str
    policy: str
    robot: dict[str, Any]


def _run_job(job: EvalJob, cache: dict[str, Benchmark] = {}) -> EpisodeResult:  # noqa: B006 - per-process cache
    if job.bench not in cache:
        cache[job.bench] = open_benchmark(job.bench)
    episode = cache[job.bench].episode(job.episode_id)
    config = RobotConfig.model_validate(job.robot)
    return run_episode(episode, load_policy(job.policy), make_collider(episode, config), config)


def iter_eval(
    bench: Benchmark, policy: str, robot: RobotConfig, episodes: list[Episode] | None = None, workers: int = 1
) -> Iterator[EpisodeResult]:
    """Evaluate ``policy`` on every episode (or ``episodes``); results stream in completion order."""
    ids = [e.episode_id for e in episodes] if episodes is not None else bench.episode_ids()
    jobs = [EvalJob(str(bench.root), eid, policy, robot.model_dump()) for eid in ids]
    if workers <= 1:
        for job in jobs:
            yield _run_job(job)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        for future in as_completed([pool.submit(_run_job, job) for job in jobs]):
            yield future.result()


def results_table(results: list[EpisodeResult], policy: str) -> pa.Table:
    """Per-episode results, sorted by episode id (deterministic bytes for a deterministic policy)."""
    rows = []
    for r in sorted(results, key=lambda r: r.episode_id):
        m = r.metrics
        rows.append(
            {
                "episode_id": r.episode_id,
                "scene_id": r.scene_id,
                "difficulty": r.difficulty,
                "policy": policy,
                "outcome": r.outcome,
                "steps": r.steps,
                "time": m.time,
                "length": m.length,
                "optimal_length": m.optimal_length,
                "optimal_time": m.optimal_time,
                "obstacle_collisions": r.obstacle_collisions,
                "max_gaussian_count": r.max_gaussian_count,
                "psc": m.psc,
                "min_distance": m.min_distance,
                "jerk": m.jerk,
                "trajectory": r.trajectory.tolist(),
                "events": [{"step": step, "kind": kind} for step, kind in r.events],
            }
        )
    return pa.Table.from_pylist(rows, RESULTS_SCHEMA)


def summarize(results: list[EpisodeResult]) -> dict[str, dict[str, float]]:
    """The metric row per difficulty (hard, medium, easy order as in the paper) and overall."""
    by = {}
    for difficulty in ("easy", "medium", "hard"):
        subset = [r.metrics for r in results if r.difficulty == difficulty]
        if subset:
            by[difficulty] = aggregate(subset)
    by["all"] = aggregate([r.metrics for r in results])
    return by


def write_results(out_dir: Path, policy: str, results: list[EpisodeResult], bench: Benchmark) -> dict[str, Any]:
    """Write ``<policy>.parquet``, ``<policy>.json`` and ``<policy>.md`` into ``out_dir``."""
    import io

    out_dir.mkdir(parents=True, exist_ok=True)
    safe = policy.replace(":", "_").replace("/", "_")
    buffer = io.BytesIO()
    pq.write_table(results_table(results, policy), buffer, compression="zstd")
    write_bytes_atomic(out_dir / f"{safe}.parquet", buffer.getvalue())
    summary = {"benchmark": str(bench.root), "version": bench.version, "policy": policy, "metrics": summarize(results)}
    write_json_atomic(out_dir / f"{safe}.json", json.loads(json.dumps(summary, allow_nan=True).replace("NaN", "null")))
    write_text_atomic(out_dir / f"{safe}.md", markdown_table({policy: summary["metrics"]}))
    return summary


def collider_for(episode: Episode, robot: RobotConfig) -> AvatarCollider:
    """The avatar collider an evaluation uses (kept as a seam for tests)."""
    return make_collider(episode, robot)


ProgressCallback = Callable[[EpisodeResult], None]
