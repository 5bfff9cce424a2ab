"""``song collect``: roll a policy out on a release's episodes and write an imitation-learning dataset.

The paper fine-tunes NavDP on trajectories replayed from training episodes; this writes such rollouts as
a LeRobot dataset (:mod:`song.runtime.lerobot`: codebase v3.0, what LeRobot's current release reads, or
v2.1 for older stacks), so LeRobot's loaders and tools read them as they are.

Per step: the chosen sensors' observations *before* the action, as features derived from each
sensor's declared space (:func:`plan_features`; any registered sensor can be recorded): a vector
space becomes ``observation.<sensor>`` (float32, flattened; a dict of vectors is concatenated in its
order, e.g. ``state`` → pose x, y, yaw, last command v, ω, goal in the robot frame x, y, goal distance
and bearing, time, named from the space); a depth image becomes ``observation.<sensor>`` (uint16
millimetres, (height, width), 0 = no depth: the RealSense convention); a colour image becomes a
video ``observation.images.<sensor>``. Then the action ``[v, ω]`` as executed (clipped to the robot's
limits), the reward terms of the Gymnasium env (progress toward the goal, ±10 at success / collision)
and their sum, and the done flags. By default only successful rollouts are written (``keep="success"``,
what behaviour cloning wants); ``keep="all"`` writes every one (``next.success`` tells them apart).
Episodes roll out in parallel worker processes and are written in release order.

Atomic per dataset: everything is written under ``DS/.partial/`` and moved into place when whole
(``meta/`` last), so a collect killed midway leaves no truncated dataset, only ``.partial``, which the
next collect into the same folder removes. One collect at a time writes a folder (a lock).

Deterministic: the same release, policy and options give byte-identical files whatever the worker
count (x264 runs single-threaded).
"""

from __future__ import annotations

import dataclasses
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.bench import open_benchmark
from song.errors import SongError
from song.runtime.ablation import without_avatars
from song.runtime.env import reward_terms
from song.runtime.guard import DEFAULT_STEP_TIMEOUT_S
from song.runtime.lerobot import FORMATS, PARTIAL_DIR, write_dataset
from song.runtime.loop import EpisodeRunner, reactive_setup, run_episode
from song.runtime.policies import load_policy, policy_sensors
from song.runtime.sensors import Box, SensorSuite, parse_sensor_names
from song.util import folder_lock

LOCK_FILE = ".song.lock"  # held while a collect writes the dataset folder


@dataclass
class CollectSummary:
    """What a collection wrote."""

    out: Path
    episodes: int  # written
    frames: int  # steps written
    successes: int  # successful rollouts (written or not)
    rollouts: int


@dataclass(frozen=True)
class FeaturePlan:
    """How one sensor (or one entry of a sensor's dict space) is stored: its LeRobot key and declaration."""

    key: str
    sensor: str
    entries: tuple[str, ...]  # the dict entries concatenated, () for a plain Box
    kind: str  # "vector" (float32), "depth" (uint16 mm image) or "video" (uint8 colour image)
    spec: dict[str, Any]

    def extract(self, observation: dict[str, Any]) -> np.ndarray:
        """This feature's value at one step, in its stored dtype (a video frame stays (H, W, 3))."""
        value = observation[self.sensor]
        if self.entries and self.kind != "vector":  # an image entry of a dict space
            value = value[self.entries[0]]
        elif self.entries:
            value = np.concatenate([np.asarray(value[e], np.float64).ravel() for e in self.entries])
        if self.kind == "video":
            return np.asarray(value, np.uint8)
        if self.kind == "depth":
            return depth_to_mm(value)
        return np.asarray(value, np.float32).ravel()


def depth_to_mm(depth_m: np.ndarray) -> np.ndarray:
    """Depth in metres → uint16 millimetres, 0 where there is no depth (not finite, ≤ 0 or beyond 65.5 m)."""
    depth = np.asarray(depth_m, np.float64)
    valid = np.isfinite(depth) & (depth > 0) & (depth < 65.535)
    return np.where(valid, np.rint(np.where(valid, depth, 0.0) * 1000.0), 0).astype(np.uint16)


def _leaf_names(key: str, box: Box) -> list[str]:
    size = int(np.prod(box.shape))
    return (
        list(box.names)
        if box.names and len(box.names) == size
        else [key]
        if size == 1
        else [f"{key}_{i}" for i in range(size)]
    )


def _plan(sensor: str, key: str, box: Box, fps: float) -> FeaturePlan:
    if box.image and np.dtype(box.dtype) == np.uint8:
        h, w = box.shape[:2]
        h, w = h - h % 2, w - w % 2  # the codec's even size
        info = {
            "video.height": h,
            "video.width": w,
            "video.codec": "h264",
            "video.pix_fmt": "yuv420p",
            "video.is_depth_map": False,
            "video.fps": fps,
            "video.channels": 3,
            "has_audio": False,
        }
        spec = {"dtype": "video", "shape": [h, w, 3], "names": ["height", "width", "channels"], "info": info}
        return FeaturePlan(f"observation.images.{key}", sensor, (), "video", spec)
    if box.image:
        h, w = box.shape[:2]
        spec = {"dtype": "uint16", "shape": [h, w], "names": ["height", "width"], "info": {"unit": "mm", "no_depth": 0}}
        return FeaturePlan(f"observation.{key}", sensor, (), "depth", spec)
    names = list(box.names) if box.names else None
    spec = {"dtype": "float32", "shape": [int(np.prod(box.shape))], "names": names}
    return FeaturePlan(f"observation.{key}", sensor, (), "vector", spec)


def plan_features(suite: SensorSuite, chosen: tuple[str, ...], fps: float) -> list[FeaturePlan]:
    """The dataset features of the chosen sensors, read from their declared spaces (LeRobot's rule).

    A dict space of vectors becomes one concatenated vector named from its entries; a dict holding
    images becomes one feature per entry (``observation.<sensor>.<entry>``).
    """
    plans = []
    for name in chosen:
        space = suite.sensors[name].space()
        if not isinstance(space, dict):
            plans.append(_plan(name, name, space, fps))
        elif not any(box.image for box in space.values()):
            names = [n for key, box in space.items() for n in _leaf_names(key, box)]
            spec = {"dtype": "float32", "shape": [len(names)], "names": names}
            plans.append(FeaturePlan(f"observation.{name}", name, tuple(space), "vector", spec))
        else:
            for key, box in space.items():
                plans.append(dataclasses.replace(_plan(name, f"{name}.{key}", box, fps), entries=(key,)))
    return plans


@dataclass(frozen=True)
class CollectJob:
    """One episode to roll out (picklable for worker processes)."""

    bench: str
    episode_id: str
    policy: str
    sensors: tuple[str, ...]
    camera: dict[str, Any]
    step_timeout_s: float
    no_avatars: bool = False
    reactive: bool = False


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
    """Roll one episode out (:func:`record_rollout`) with the job's policy."""
    if job.bench not in cache:
        cache[job.bench] = open_benchmark(job.bench)
    bench = cache[job.bench]
    episode = dataclasses.replace(bench.episode(job.episode_id), params=bench.params)
    if job.no_avatars:
        episode = without_avatars(episode)
    policy = load_policy(job.policy)
    return record_rollout(bench, episode, policy, job.sensors, job.camera, job.step_timeout_s, job.reactive)[0]


def record_rollout(
    bench: Any,
    episode: Any,
    policy: Any,
    sensors: tuple[str, ...],
    camera: dict[str, Any],
    step_timeout_s: float | None = DEFAULT_STEP_TIMEOUT_S,
    reactive: bool = False,
) -> tuple[dict[str, Any], Any]:
    """Run ``policy`` on ``episode`` with :func:`run_episode`, recording every step; (record, result).

    ``reactive``: pedestrians near the robot avoid it (:mod:`song.runtime.reactive`).

    Per step: the observation before acting, the executed action and the reward terms (the Gymnasium
    env's, :func:`song.runtime.env.reward_terms`). The record is what :func:`song.runtime.lerobot.write_dataset` writes.
    """
    recorder = _Recorder(policy)
    names = tuple(dict.fromkeys([*policy_sensors(policy), *sensors]))
    suite = SensorSuite.build(names, bench.params, bench.max_pedestrians, {"camera": dict(camera)})
    plans = plan_features(suite, sensors, float(bench.params.robot.control_hz))
    steps: dict[str, list] = {k: [] for k in (*(p.key for p in plans), "action", "progress", "terminal")}

    def record(runner: EpisodeRunner) -> None:
        obs = recorder.observation
        before, after = (float(np.linalg.norm(p.xy - episode.goal_xy)) for p in runner.poses[-2:])
        progress, terminal = reward_terms(before, after, runner.outcome)
        steps["progress"].append(progress)
        steps["terminal"].append(terminal)
        steps["action"].append(np.asarray(runner.command, np.float32))
        for plan in plans:
            steps[plan.key].append(plan.extract(obs))

    episode, collider, crowd = reactive_setup(episode, reactive)
    result = run_episode(episode, recorder, collider, suite, record, step_timeout_s, crowd)
    out: dict[str, Any] = {
        "episode_id": episode.episode_id,
        "difficulty": episode.difficulty,
        "outcome": result.outcome,
    }
    for name, values in steps.items():
        if values:
            out[name] = np.stack(values)
    out["steps"] = len(steps["action"])
    out["plans"] = plans
    return out, result


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
    allow_modified: bool = False,
    no_avatars: bool = False,
    dataset_format: str = "v3.0",
    reactive: bool = False,
) -> CollectSummary:
    """Roll ``policy_name`` out on the ``split`` episodes of a release into a LeRobot dataset at ``out``.

    Args:
        bench_path: the release (a folder, ``DIR@X.Y.Z`` or a release folder).
        policy_name: the expert: a baseline name or ``module:Class``.
        out: the dataset folder to create (must not exist or be empty).
        split: which split's episodes.
        sensors: what to record: any sensors (their declared spaces decide how, :func:`plan_features`).
        limit: only the first N episodes of the split.
        camera: camera sensors' options (``width``, ``height``, ``backend``).
        keep: ``success`` writes only successful rollouts (what behaviour cloning wants), ``all`` every one.
        workers: processes rolling episodes out in parallel (files are written in release order, so
            the dataset does not depend on the worker count).
        step_timeout_s: a policy call taking longer fails its episode.
        allow_modified: collect from a release that fails its integrity check (recorded in ``info.json``).
        no_avatars: the avatar-free ablation: episodes without pedestrians (recorded in ``info.json``).
        dataset_format: LeRobot codebase version to write, ``v3.0`` (LeRobot's current release) or ``v2.1``.
        reactive: pedestrians near the robot avoid it (:mod:`song.runtime.reactive`; recorded in ``info.json``).

    Raises:
        SongError: an unknown sensor, ``keep`` or format, an existing non-empty ``out``, or an unknown split.
    """
    from song.parallel import parallel_map

    chosen = parse_sensor_names(sensors)  # any registered sensor: its space says how it is stored
    if keep not in ("success", "all"):
        raise SongError(f"collect: --keep {keep!r}: use success or all")
    if dataset_format not in FORMATS:
        raise SongError(f"collect: --format {dataset_format!r}: use one of {', '.join(FORMATS)}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise SongError(f"{out}: a file; collect writes a dataset folder (choose another --out)")
    refuse_non_empty(out)
    bench = open_benchmark(bench_path)
    bench.require_intact(allow_modified)
    episodes = list(bench.episodes(split=split))[: limit if limit is not None else None]
    if not episodes:
        raise SongError(f"{bench_path}: no '{split}' episodes to collect")
    load_policy(policy_name)  # an unknown policy fails here, before anything is written
    out.mkdir(parents=True, exist_ok=True)
    with folder_lock(out / LOCK_FILE, "dataset folder"):  # a second collect into --out stops at once
        refuse_non_empty(out)  # checked again under the lock
        partial = out / PARTIAL_DIR  # what a killed collect left (we hold the lock: nobody is writing it)
        shutil.rmtree(partial, ignore_errors=True)
        fps = float(bench.params.robot.control_hz)
        jobs = [
            CollectJob(
                str(bench.root),
                e.episode_id,
                policy_name,
                chosen,
                dict(camera or {}),
                step_timeout_s,
                no_avatars,
                reactive,
            )  # fmt: skip
            for e in episodes
        ]
        done = {r["episode_id"]: r for r in parallel_map(_collect_job, jobs, workers)}
        rollouts = [done[e.episode_id] for e in episodes]  # in release order, whatever the workers
        kept = [r for r in rollouts if r["steps"] and (keep == "all" or r["outcome"] == "success")]
        successes = sum(r["outcome"] == "success" for r in rollouts)
        about = {"release": str(bench.version), "fingerprint": bench.info.fingerprint, "policy": policy_name,
                 "split": split, "keep": keep, "rollouts": len(rollouts), "successes": successes,
                 "release_check": bench.integrity or "ok", "ablation": "no_avatars" if no_avatars else None,
                 "pedestrians": "reactive" if reactive else "replay"}  # fmt: skip
        frames = write_dataset(out, kept, fps, split, about, dataset_format)
        return CollectSummary(out, len(kept), frames, successes, len(rollouts))


def refuse_non_empty(out: Path, writer: str = "collect") -> None:
    """Refuse an ``out`` holding anything but the lock and what a killed writer left."""
    if out.is_dir() and any(p.name not in (LOCK_FILE, PARTIAL_DIR) for p in out.iterdir()):
        raise SongError(f"{out}: not empty; {writer} writes a new dataset (choose another --out)")
