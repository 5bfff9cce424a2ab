"""``song collect``: roll a policy out on a release's episodes and write an imitation-learning dataset.

The paper fine-tunes NavDP on trajectories replayed from training episodes; this writes such rollouts in
the LeRobot dataset layout (codebase v2.1), so LeRobot's loaders and tools read them as they are:

    DS/meta/info.json            features (dtype, shape, names), fps, counts, path templates, splits
    DS/meta/episodes.jsonl       one line per episode: index, tasks, length, and SONG's episode id, outcome
    DS/meta/episodes_stats.jsonl per-episode min / max / mean / std / count of every numeric feature
    DS/meta/tasks.jsonl          the one task ("navigate to the goal among pedestrians")
    DS/data/chunk-000/episode_000000.parquet   one row per control step
    DS/videos/chunk-000/observation.images.rgb/episode_000000.mp4   image streams (H.264)

Per step: the chosen sensors' observations *before* the action (``state`` → ``observation.state``, a
10-vector: pose x, y, yaw, last command v, ω, goal in the robot frame x, y, goal distance and bearing,
time; ``scan``, ``pedestrians`` → flat vectors; ``depth`` → ``observation.depth``, metres, float16,
flattened row-major; ``rgb`` → a video), the action ``[v, ω]`` as executed (clipped to the robot's
limits), the reward terms of the Gymnasium env (progress toward the goal, ±10 at success / collision)
and their sum, and the done flags. By default only successful rollouts are written (``keep="success"``,
what behaviour cloning wants); ``keep="all"`` writes every one (``next.success`` tells them apart).
Episodes roll out in parallel worker processes and are written in release order.

Deterministic: the same release, policy and options give byte-identical files whatever the worker
count (x264 runs single-threaded). Checked against the layout as LeRobot documents it (the ``lerobot``
package itself pulls a large dependency tree that is not installed here).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.bench import open_benchmark
from song.errors import SongError
from song.runtime.avatars import make_collider
from song.runtime.env import reward_terms
from song.runtime.guard import DEFAULT_STEP_TIMEOUT_S
from song.runtime.loop import EpisodeRunner, run_episode
from song.runtime.policies import load_policy, policy_sensors
from song.runtime.sensors import SensorSuite, parse_sensor_names
from song.util import write_json_atomic, write_text_atomic

CODEBASE_VERSION = "v2.1"
CHUNK_SIZE = 1000
TASK = "navigate to the goal among pedestrians"
STATE_NAMES = ["x", "y", "yaw", "v", "omega", "goal_x", "goal_y", "goal_distance", "goal_bearing", "t"]
COLLECTABLE = ("state", "scan", "pedestrians", "rgb", "depth")
DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"


@dataclass
class CollectSummary:
    """What a collection wrote."""

    out: Path
    episodes: int  # written
    frames: int  # steps written
    successes: int  # successful rollouts (written or not)
    rollouts: int


def _flat_state(obs: dict[str, np.ndarray]) -> np.ndarray:
    return np.concatenate([obs["pose"], obs["velocity"], obs["goal"], obs["goal_polar"], obs["t"]]).astype(np.float32)


def _features(episode: dict[str, np.ndarray], sensors: tuple[str, ...], fps: float) -> dict[str, dict]:
    """LeRobot feature declarations, shapes read from the first collected episode."""
    out: dict[str, dict] = {}
    if "state" in sensors:
        out["observation.state"] = {"dtype": "float32", "shape": [len(STATE_NAMES)], "names": STATE_NAMES}
    for name in ("scan", "pedestrians"):
        if name in sensors:
            out[f"observation.{name}"] = {"dtype": "float32", "shape": [int(episode[name].shape[1])], "names": None}
    if "depth" in sensors:
        h, w = episode["depth_hw"]
        out["observation.depth"] = {
            "dtype": "float16",
            "shape": [h * w],
            "names": None,
            "info": {"height": h, "width": w, "unit": "m"},
        }
    if "rgb" in sensors:
        h, w = episode["rgb"].shape[1:3]
        out["observation.images.rgb"] = {
            "dtype": "video",
            "shape": [h - h % 2, w - w % 2, 3],
            "names": ["height", "width", "channels"],
            "info": {"video.fps": fps, "video.codec": "h264", "video.pix_fmt": "yuv420p", "has_audio": False},
        }
    out["action"] = {"dtype": "float32", "shape": [2], "names": ["v", "omega"]}
    for name in ("next.reward", "reward.progress", "reward.terminal", "timestamp"):
        out[name] = {"dtype": "float32", "shape": [1], "names": None}
    for name in ("next.done", "next.success"):
        out[name] = {"dtype": "bool", "shape": [1], "names": None}
    for name in ("frame_index", "episode_index", "index", "task_index"):
        out[name] = {"dtype": "int64", "shape": [1], "names": None}
    return out


@dataclass(frozen=True)
class CollectJob:
    """One episode to roll out (picklable for worker processes)."""

    bench: str
    episode_id: str
    policy: str
    sensors: tuple[str, ...]
    camera: dict[str, Any]
    step_timeout_s: float


class _Recorder:
    """Wraps a policy: remembers the observation it was last shown (the one before the step)."""

    def __init__(self, policy) -> None:
        self.policy, self.observation = policy, None

    def reset(self, episode) -> None:
        self.policy.reset(episode)

    def act(self, observation):
        self.observation = observation
        return self.policy.act(observation)


def _collect_job(job: CollectJob, cache: dict[str, Any] = {}) -> dict[str, Any]:  # noqa: B006 - per-process cache
    """Roll one episode out with :func:`run_episode`, recording every step.

    Per step: the observation before acting, the executed action and the reward terms (the Gymnasium
    env's, :func:`song.runtime.env.reward_terms`).
    """
    if job.bench not in cache:
        cache[job.bench] = open_benchmark(job.bench)
    bench = cache[job.bench]
    episode = dataclasses.replace(bench.episode(job.episode_id), params=bench.params)
    recorder = _Recorder(load_policy(job.policy))
    names = tuple(dict.fromkeys([*policy_sensors(recorder.policy), *job.sensors]))
    suite = SensorSuite.build(names, bench.params, bench.max_pedestrians, {"camera": dict(job.camera)})
    steps: dict[str, list] = {k: [] for k in (*COLLECTABLE, "action", "progress", "terminal")}

    def record(runner: EpisodeRunner) -> None:
        obs = recorder.observation
        before, after = (float(np.linalg.norm(p.xy - episode.goal_xy)) for p in runner.poses[-2:])
        progress, terminal = reward_terms(before, after, runner.outcome)
        steps["progress"].append(progress)
        steps["terminal"].append(terminal)
        steps["action"].append(np.asarray(runner.command, np.float32))
        if "state" in job.sensors:
            steps["state"].append(_flat_state(obs["state"]))
        for name in ("scan", "pedestrians"):
            if name in job.sensors:
                steps[name].append(np.asarray(obs[name], np.float32).ravel())
        if "depth" in job.sensors:
            steps["depth"].append(np.asarray(obs["depth"], np.float16))
        if "rgb" in job.sensors:
            steps["rgb"].append(np.asarray(obs["rgb"], np.uint8))

    result = run_episode(episode, recorder, make_collider(episode), suite, record, job.step_timeout_s)
    out: dict[str, Any] = {"episode_id": job.episode_id, "difficulty": episode.difficulty, "outcome": result.outcome}
    for name, values in steps.items():
        if values:
            out[name] = np.stack(values)
    if "depth" in out:
        out["depth_hw"] = out["depth"].shape[1:]
        out["depth"] = out["depth"].reshape(len(out["depth"]), -1)
    out["steps"] = len(steps["action"])
    return out


def _table(episode: dict[str, Any], sensors: tuple[str, ...], episode_index: int, first_index: int, fps: float):
    import pyarrow as pa

    n = episode["steps"]
    success = episode["outcome"] == "success"
    cols: dict[str, Any] = {}
    if "state" in sensors:
        cols["observation.state"] = pa.FixedSizeListArray.from_arrays(
            pa.array(episode["state"].ravel()), len(STATE_NAMES)
        )
    for name in ("scan", "pedestrians"):
        if name in sensors:
            cols[f"observation.{name}"] = pa.FixedSizeListArray.from_arrays(
                pa.array(episode[name].ravel()), episode[name].shape[1]
            )
    if "depth" in sensors:
        cols["observation.depth"] = pa.FixedSizeListArray.from_arrays(
            pa.array(episode["depth"].ravel()), episode["depth"].shape[1]
        )
    cols["action"] = pa.FixedSizeListArray.from_arrays(pa.array(episode["action"].ravel()), 2)
    progress = np.asarray(episode["progress"], np.float32)
    terminal = np.asarray(episode["terminal"], np.float32)
    cols["next.reward"] = progress + terminal
    cols["reward.progress"] = progress
    cols["reward.terminal"] = terminal
    done = np.zeros(n, bool)
    done[-1] = True
    cols["next.done"] = done
    cols["next.success"] = done & success
    cols["timestamp"] = (np.arange(n) / fps).astype(np.float32)
    cols["frame_index"] = np.arange(n, dtype=np.int64)
    cols["episode_index"] = np.full(n, episode_index, np.int64)
    cols["index"] = first_index + np.arange(n, dtype=np.int64)
    cols["task_index"] = np.zeros(n, np.int64)
    return pa.table(cols)


def _stats(table) -> dict[str, dict]:
    """LeRobot's per-episode statistics of every numeric column (per dimension for vectors)."""
    out = {}
    for name in table.column_names:
        values = np.asarray(table.column(name).to_pylist(), dtype=np.float64)
        if values.ndim == 1:
            values = values[:, None]
        out[name] = {
            "min": values.min(axis=0).tolist(),
            "max": values.max(axis=0).tolist(),
            "mean": values.mean(axis=0).tolist(),
            "std": values.std(axis=0).tolist(),
            "count": [int(len(values))],
        }
    return out


def collect(
    bench_path: str | Path,
    policy_name: str,
    out: str | Path,
    split: str = "train",
    sensors: tuple[str, ...] = ("state",),
    limit: int | None = None,
    camera: dict[str, Any] | None = None,
    keep: str = "success",
    workers: int = 1,
    step_timeout_s: float = DEFAULT_STEP_TIMEOUT_S,
) -> CollectSummary:
    """Roll ``policy_name`` out on the ``split`` episodes of a release into a LeRobot dataset at ``out``.

    Args:
        bench_path: the release (a folder, ``DIR@X.Y.Z`` or a release folder).
        policy_name: the expert: a baseline name or ``module:Class``.
        out: the dataset folder to create (must not exist or be empty).
        split: which split's episodes.
        sensors: what to record (see ``COLLECTABLE``).
        limit: only the first N episodes of the split.
        camera: camera sensors' options (``width``, ``height``, ``backend``).
        keep: ``success`` writes only successful rollouts (what behaviour cloning wants), ``all`` every one.
        workers: processes rolling episodes out in parallel (files are written in release order, so
            the dataset does not depend on the worker count).
        step_timeout_s: a policy call taking longer fails its episode.

    Raises:
        SongError: an unknown sensor or ``keep``, an existing non-empty ``out``, or an unknown split.
    """
    import pyarrow.parquet as pq

    from song.parallel import parallel_map

    chosen = parse_sensor_names(sensors)
    unknown = [s for s in chosen if s not in COLLECTABLE]
    if unknown:
        raise SongError(f"collect: sensor '{unknown[0]}' cannot be recorded; use any of {', '.join(COLLECTABLE)}")
    if keep not in ("success", "all"):
        raise SongError(f"collect: --keep {keep!r}: use success or all")
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise SongError(f"{out}: not empty; collect writes a new dataset (choose another --out)")
    bench = open_benchmark(bench_path)
    episodes = list(bench.episodes(split=split))[: limit if limit is not None else None]
    if not episodes:
        raise SongError(f"{bench_path}: no '{split}' episodes to collect")
    load_policy(policy_name)  # an unknown policy fails here, before any work
    fps = float(bench.params.robot.control_hz)
    jobs = [
        CollectJob(str(bench.root), e.episode_id, policy_name, chosen, dict(camera or {}), step_timeout_s)
        for e in episodes
    ]
    done = {r["episode_id"]: r for r in parallel_map(_collect_job, jobs, workers)}
    features: dict[str, dict] | None = None
    lines, stats_lines, total, successes, index = [], [], 0, 0, 0
    for episode in episodes:
        result = done[episode.episode_id]
        successes += result["outcome"] == "success"
        if result["steps"] == 0 or (keep == "success" and result["outcome"] != "success"):
            continue
        features = features or _features(result, chosen, fps)
        chunk = index // CHUNK_SIZE
        table = _table(result, chosen, index, total, fps)
        path = out / DATA_PATH.format(episode_chunk=chunk, episode_index=index)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path, compression="zstd")
        if "rgb" in chosen:
            from song.render.video import write_mp4

            video = out / VIDEO_PATH.format(
                episode_chunk=chunk, video_key="observation.images.rgb", episode_index=index
            )
            video.parent.mkdir(parents=True, exist_ok=True)
            write_mp4(video, result["rgb"], fps)
        lines.append(
            {"episode_index": index, "tasks": [TASK], "length": result["steps"], "song_episode_id": episode.episode_id,
             "outcome": result["outcome"], "difficulty": result["difficulty"]}
        )  # fmt: skip
        stats_lines.append({"episode_index": index, "stats": _stats(table)})
        total += result["steps"]
        index += 1
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": "song_differential_drive",
        "total_episodes": len(lines),
        "total_frames": total,
        "total_tasks": 1,
        "total_videos": len(lines) if "rgb" in chosen else 0,
        "total_chunks": max(1, (len(lines) - 1) // CHUNK_SIZE + 1),
        "chunks_size": CHUNK_SIZE,
        "fps": fps,
        "splits": {split: f"0:{len(lines)}"},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if "rgb" in chosen else None,
        "features": features or {},
        "song": {
            "release": str(bench.version),
            "fingerprint": bench.info.fingerprint,
            "policy": policy_name,
            "split": split,
            "keep": keep,
            "rollouts": len(episodes),
            "successes": successes,
        },
    }
    meta = out / "meta"
    meta.mkdir(parents=True, exist_ok=True)
    write_json_atomic(meta / "info.json", info)
    write_text_atomic(meta / "episodes.jsonl", "".join(json.dumps(x, sort_keys=True) + "\n" for x in lines))
    write_text_atomic(meta / "episodes_stats.jsonl", "".join(json.dumps(x, sort_keys=True) + "\n" for x in stats_lines))
    write_text_atomic(meta / "tasks.jsonl", json.dumps({"task_index": 0, "task": TASK}) + "\n")
    return CollectSummary(out, len(lines), total, successes, len(episodes))
