"""Reactive pedestrians: the online crowd step's cost per control step, and what it changes, one JSON object.

.venv/bin/python benchmarks/reactive.py [--pedestrians 20] [--bench runs/demo-bench --episodes 40]

Synthetic (always): a 10 × 6 m room, ``--pedestrians`` people walking straight across it in both
directions (0.8–1.4 m/s, seeded), all within 3 m of a robot that drives through the middle at 0.5 m/s
(so every one of them reacts at some step, most at many). We time :meth:`ReactiveCrowd.advance` per
control step (thread CPU time and wall time) and report its median, p95 and max, with the number of
pedestrians reacting in that step. The issue's target: ≤ 5 ms per control step for 20 pedestrians.

With ``--bench``: the first ``--episodes`` test episodes of a release, the ``astar`` baseline, replay
and reactive pedestrians, with the outcome counts and the human-collision rate of each; with
``--figure PNG`` too, the first of those episodes where the replayed crowd runs into the robot and the
reactive one does not: the robot camera 2 s, 1 s and 0 s before the replay's collision, and the map at
that moment (replay above, reactive pedestrians below).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

sys.path.insert(0, str(ROOT))
from song.config import RobotConfig  # noqa: E402
from song.runtime.loop import EpisodeRunner, reactive_setup  # noqa: E402
from tests.runtime.helpers import episode, track  # noqa: E402


def synthetic(count: int, seed: int = 0) -> dict:
    """Time the crowd step around a robot driving through ``count`` crossing pedestrians."""
    rng = np.random.default_rng(seed)
    peds = []
    for k in range(count):
        y0, y1 = rng.uniform(0.6, 5.4, 2)
        start, end = ((0.6, y0), (9.4, y1)) if k % 2 else ((9.4, y0), (0.6, y1))
        peds.append(track(k, start, end, t0=float(rng.uniform(-4.0, 2.0)), speed=float(rng.uniform(0.8, 1.4))))
    ep = episode(start=(1.0, 3.0), goal=(9.0, 3.0), peds=peds, robot=RobotConfig(max_steps=160))
    reactive, collider, crowd = reactive_setup(ep)
    runner = EpisodeRunner(reactive, collider, None, None)  # the crowd is stepped here, timed
    cpu, wall, reacting = [], [], []
    while runner.outcome is None:
        before = runner.time
        runner.step(0.5, 0.0)
        c0, w0 = time.thread_time(), time.perf_counter()
        crowd.advance(before, runner.time, runner.pose.xy, np.array([0.5, 0.0]))
        cpu.append((time.thread_time() - c0) * 1000)
        wall.append((time.perf_counter() - w0) * 1000)
        reacting.append(int((np.hypot(*crowd.offset.T) > 0).sum()))
    cpu, wall = np.array(cpu), np.array(wall)
    return {
        "pedestrians": count,
        "control_steps": len(cpu),
        "reacting_per_step_median": float(np.median(reacting)),
        "reacting_per_step_max": int(max(reacting)),
        "cpu_ms_per_step": {
            "median": round(float(np.median(cpu)), 3),
            "p95": round(float(np.percentile(cpu, 95)), 3),
            "max": round(float(cpu.max()), 3),
        },
        "wall_ms_per_step": {
            "median": round(float(np.median(wall)), 3),
            "p95": round(float(np.percentile(wall, 95)), 3),
        },
        "target_ms": 5.0,
    }


def release(bench: str, episodes: int) -> dict:
    """Outcomes of the astar baseline on the first ``episodes`` test episodes, replay and reactive."""
    from song.datasets.bench import open_benchmark
    from song.runtime.evaluate import iter_eval, make_setup, summarize

    opened = open_benchmark(bench)
    chosen = list(opened.episodes(split="test"))[:episodes]
    out = {}
    for reactive in (False, True):
        setup = make_setup(opened, "astar", reactive=reactive)
        start = time.perf_counter()
        results = list(iter_eval(opened, setup, chosen))
        seconds = time.perf_counter() - start
        row = summarize(results)["all"]
        steps = sum(r.steps for r in results)
        out["reactive" if reactive else "replay"] = {
            "episodes": len(results),
            **{k: round(float(row[k]), 2) for k in ("SR", "CR_hum", "CR_obs", "TO", "PSC", "MinD")},
            "steps_per_s": round(steps / seconds, 1),
        }
    return out


def _rollout(bench, chosen, reactive: bool, pictures=None, at=()):
    """``astar`` on one episode: (runner at the end, pictures at the steps ``at``)."""
    import dataclasses

    from song.runtime.guard import policy_view
    from song.runtime.policies import load_policy
    from song.runtime.sensors import SensorSuite

    chosen, collider, crowd = reactive_setup(dataclasses.replace(chosen, params=bench.params), reactive)
    policy = load_policy("astar")
    sensors = SensorSuite.build(("state",), bench.params, bench.max_pedestrians)
    runner = EpisodeRunner(chosen, collider, sensors, crowd)
    policy.reset(policy_view(chosen, sensors.names))
    frames = []
    while runner.outcome is None:
        runner.step(*np.asarray(policy.act(runner.observation()), float))
        if pictures is not None and runner.step_index in at:
            frames.append(pictures.frame(runner))
    return runner, frames


def figure(bench_path: str, episodes: int, out: Path) -> str | None:
    """Write the replay-vs-reactive picture (see the module doc); the episode shown, or None."""
    from PIL import Image

    from song.datasets.bench import open_benchmark
    from song.runtime.pictures import PANEL_HEIGHT, PovPictures

    bench = open_benchmark(bench_path)
    for shown in list(bench.episodes(split="test"))[:episodes]:
        replay, _ = _rollout(bench, shown, False)
        if replay.outcome == "human" and _rollout(bench, shown, True)[0].outcome != "human":
            break
    else:
        return None
    hz = float(bench.params.robot.control_hz)
    at = {max(1, replay.step_index - int(k * hz)) for k in (2, 1, 0)}
    pictures = PovPictures(bench.params, bench.max_pedestrians, {"width": 320, "height": 240})
    width = round(PANEL_HEIGHT * 320 / 240)  # each picture: RGB | depth | map; we keep the RGB, and the last map
    rows = []
    for reactive in (False, True):
        frames = _rollout(bench, shown, reactive, pictures, at)[1]
        rows.append(np.concatenate([f[:, :width] for f in frames] + [frames[-1][:, 2 * width :]], axis=1))
    image = Image.fromarray(np.concatenate(rows, axis=0))
    image.thumbnail((1800, 1800))
    out.parent.mkdir(parents=True, exist_ok=True)
    image.save(out)
    return shown.episode_id


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pedestrians", type=int, default=20)
    parser.add_argument("--bench", default=None, help="a release to compare replay and reactive on")
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--figure", type=Path, default=None, help="with --bench: write the replay/reactive picture")
    args = parser.parse_args()
    report = {"synthetic": synthetic(args.pedestrians)}
    if args.bench:
        report["release"] = release(args.bench, args.episodes)
        if args.figure:
            report["figure"] = {"path": str(args.figure), "episode": figure(args.bench, args.episodes, args.figure)}
    emit(report)


if __name__ == "__main__":
    main()
