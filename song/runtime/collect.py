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
and their sum, and the done flags. Rows of an episode that ended by collision or time-out are kept
(``next.success`` says which ones succeeded; filter them for behaviour cloning).

Deterministic: the same release, policy and options give byte-identical files (x264 single-threaded).
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
from song.runtime.env import SUCCESS_REWARD
from song.runtime.guard import DEFAULT_STEP_TIMEOUT_S, PolicyFailure, as_command, call_policy, frozen_copy
from song.runtime.loop import EpisodeRunner
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
    episodes: int
    frames: int
    successes: int


def _flat_state(obs: dict[str, np.ndarray]) -> np.ndarray:
    return np.concatenate([obs["pose"], obs["velocity"], obs["goal"], obs["goal_polar"], obs["t"]]).astype(np.float32)


def _features(observation: dict[str, Any], sensors: tuple[str, ...], fps: float) -> dict[str, dict]:
    """LeRobot feature declarations, shapes read from the first observation."""
    out: dict[str, dict] = {}
    if "state" in sensors:
        out["observation.state"] = {"dtype": "float32", "shape": [len(STATE_NAMES)], "names": STATE_NAMES}
    for name in ("scan", "pedestrians"):
        if name in sensors:
            out[f"observation.{name}"] = {"dtype": "float32", "shape": [int(np.size(observation[name]))], "names": None}
    if "depth" in sensors:
        h, w = np.shape(observation["depth"])
        out["observation.depth"] = {
            "dtype": "float16",
            "shape": [h * w],
            "names": None,
            "info": {"height": h, "width": w, "unit": "m"},
        }
    if "rgb" in sensors:
        h, w = np.shape(observation["rgb"])[:2]
        out["observation.images.rgb"] = {
            "dtype": "video",
            "shape": [h - h % 2, w - w % 2, 3],
            "names": ["height", "width", "channels"],
            "info": {"video.fps": fps, "video.codec": "h264", "video.pix_fmt": "yuv420p", "has_audio": False},
        }
    out["action"] = {"dtype": "float32", "shape": [2], "names": ["v", "omega"]}
    for name in ("next.reward", "reward.progress", "reward.terminal"):
        out[name] = {"dtype": "float32", "shape": [1], "names": None}
    for name in ("next.done", "next.success"):
        out[name] = {"dtype": "bool", "shape": [1], "names": None}
    for name in ("timestamp",):
        out[name] = {"dtype": "float32", "shape": [1], "names": None}
    for name in ("frame_index", "episode_index", "index", "task_index"):
        out[name] = {"dtype": "int64", "shape": [1], "names": None}
    return out


def _rollout(episode, policy, sensors: SensorSuite, step_timeout_s: float) -> tuple[list[dict], list[np.ndarray], str]:
    """Run one episode; per step the observation before acting, the action, the reward terms, done flags."""
    runner = EpisodeRunner(episode, make_collider(episode), sensors)
    rows, frames = [], []
    try:
        call_policy(policy.reset, frozen_copy(episode), what="reset()", timeout_s=step_timeout_s)
        while runner.outcome is None:
            obs = runner.observation()
            action = call_policy(policy.act, obs, what="act()", timeout_s=step_timeout_s)
            before = float(np.linalg.norm(runner.pose.xy - episode.goal_xy))
            outcome = runner.step(*as_command(action))
            after = float(np.linalg.norm(runner.pose.xy - episode.goal_xy))
            terminal = (
                SUCCESS_REWARD if outcome == "success" else -SUCCESS_REWARD if outcome in ("obstacle", "human") else 0.0
            )
            rows.append(
                {"obs": obs, "action": np.asarray(runner.command, np.float32), "progress": before - after, "terminal": terminal,
                 "done": outcome is not None}
            )  # fmt: skip
            if "rgb" in obs:
                frames.append(obs["rgb"])
    except PolicyFailure as exc:
        runner.fail(str(exc))
    return rows, frames, runner.outcome or "error"


def _table(rows: list[dict], sensors: tuple[str, ...], episode_index: int, first_index: int, fps: float, success: bool):
    import pyarrow as pa

    n = len(rows)
    cols: dict[str, Any] = {}
    if "state" in sensors:
        cols["observation.state"] = [_flat_state(r["obs"]["state"]).tolist() for r in rows]
    for name in ("scan", "pedestrians"):
        if name in sensors:
            cols[f"observation.{name}"] = [np.asarray(r["obs"][name], np.float32).ravel().tolist() for r in rows]
    if "depth" in sensors:
        depth = np.stack([np.asarray(r["obs"]["depth"], np.float16).ravel() for r in rows])
        cols["observation.depth"] = pa.FixedSizeListArray.from_arrays(pa.array(depth.ravel()), depth.shape[1])
    cols["action"] = [r["action"].tolist() for r in rows]
    progress = np.array([r["progress"] for r in rows], np.float32)
    terminal = np.array([r["terminal"] for r in rows], np.float32)
    cols["next.reward"] = progress + terminal
    cols["reward.progress"] = progress
    cols["reward.terminal"] = terminal
    cols["next.done"] = np.array([r["done"] for r in rows])
    cols["next.success"] = np.array([r["done"] and success for r in rows])
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
        column = table.column(name).to_pylist()
        values = np.asarray(column, dtype=np.float64)
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
    step_timeout_s: float = DEFAULT_STEP_TIMEOUT_S,
) -> CollectSummary:
    """Roll ``policy_name`` out on the ``split`` episodes of a release into a LeRobot dataset at ``out``.

    Raises:
        SongError: an unknown sensor, an existing non-empty ``out``, or an unknown split.
    """
    import pyarrow.parquet as pq

    chosen = parse_sensor_names(sensors)
    unknown = [s for s in chosen if s not in COLLECTABLE]
    if unknown:
        raise SongError(f"collect: sensor '{unknown[0]}' cannot be recorded; use any of {', '.join(COLLECTABLE)}")
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise SongError(f"{out}: not empty; collect writes a new dataset (choose another --out)")
    bench = open_benchmark(bench_path)
    episodes = list(bench.episodes(split=split))[: limit if limit is not None else None]
    if not episodes:
        raise SongError(f"{bench_path}: no '{split}' episodes to collect")
    policy = load_policy(policy_name)
    names = tuple(dict.fromkeys([*policy_sensors(policy), *chosen]))
    options = {"camera": dict(camera or {})}
    suite = SensorSuite.build(names, bench.params, bench.max_pedestrians, options)
    fps = float(bench.params.robot.control_hz)
    features: dict[str, dict] | None = None
    lines, stats_lines, total, successes = [], [], 0, 0
    for index, episode in enumerate(episodes):
        episode = dataclasses.replace(episode, params=bench.params)
        rows, frames, outcome = _rollout(episode, policy, suite, step_timeout_s)
        if not rows:
            continue
        features = features or _features(rows[0]["obs"], chosen, fps)
        chunk = index // CHUNK_SIZE
        table = _table(rows, chosen, index, total, fps, outcome == "success")
        path = out / DATA_PATH.format(episode_chunk=chunk, episode_index=index)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path, compression="zstd")
        if "rgb" in chosen:
            from song.viz.draw import write_mp4

            video = out / VIDEO_PATH.format(
                episode_chunk=chunk, video_key="observation.images.rgb", episode_index=index
            )
            video.parent.mkdir(parents=True, exist_ok=True)
            write_mp4(video, frames, fps)
        lines.append(
            {"episode_index": index, "tasks": [TASK], "length": len(rows), "song_episode_id": episode.episode_id,
             "outcome": outcome, "difficulty": episode.difficulty}
        )  # fmt: skip
        stats_lines.append({"episode_index": index, "stats": _stats(table)})
        total += len(rows)
        successes += outcome == "success"
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": "song_differential_drive",
        "total_episodes": len(lines),
        "total_frames": total,
        "total_tasks": 1,
        "total_videos": len(lines) if "rgb" in chosen else 0,
        "total_chunks": (len(episodes) - 1) // CHUNK_SIZE + 1,
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
        },
    }
    meta = out / "meta"
    meta.mkdir(parents=True, exist_ok=True)
    write_json_atomic(meta / "info.json", info)
    write_text_atomic(meta / "episodes.jsonl", "".join(json.dumps(x, sort_keys=True) + "\n" for x in lines))
    write_text_atomic(meta / "episodes_stats.jsonl", "".join(json.dumps(x, sort_keys=True) + "\n" for x in stats_lines))
    write_text_atomic(meta / "tasks.jsonl", json.dumps({"task_index": 0, "task": TASK}) + "\n")
    return CollectSummary(out, len(lines), total, successes)
