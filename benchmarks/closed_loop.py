"""Closed-loop speed of the vision baseline: steps per second of ``song eval --policy depth`` on a release.

    .venv/bin/python benchmarks/closed_loop.py --bench runs/demo-bench [--resolution 320x240] [--episodes 12]

Runs the depth baseline on the first ``--episodes`` test episodes in one process, exactly as
``song eval --policy depth -j 1`` does per episode (the policy's sensors built for the release, the
avatar collider, :func:`song.runtime.loop.run_episode` with its step timeout), after one warm-up
episode (numba's compiled kernels loaded, the first scene read). Reports steps per second of wall time
over all episodes, the seconds per step spent rendering (from the renderer's phase profile) and the
load; the issue's target is ≥ 15 steps/s at 320×240 on 2 cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.datasets.bench import open_benchmark  # noqa: E402
from song.runtime.avatars import make_collider  # noqa: E402
from song.runtime.loop import run_episode  # noqa: E402
from song.runtime.policies import load_policy, policy_sensors  # noqa: E402
from song.runtime.sensors import SensorSuite  # noqa: E402


def main() -> None:
    import numba

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", required=True)
    parser.add_argument("--resolution", default="320x240")
    parser.add_argument("--episodes", type=int, default=12)
    parser.add_argument("--policy", default="depth")
    args = parser.parse_args()
    width, height = (int(v) for v in args.resolution.split("x"))
    bench = open_benchmark(args.bench)
    episodes = list(bench.episodes(split="test"))[: args.episodes + 1]
    policy = load_policy(args.policy)
    options = {"camera": {"width": width, "height": height}}
    suite = SensorSuite.build(policy_sensors(policy), bench.params, bench.max_pedestrians, options)
    load_start = os.getloadavg()[0]
    steps, wall, outcomes = 0, 0.0, []
    for k, summary in enumerate(episodes):
        episode = dataclasses.replace(bench.episode(summary.episode_id), params=bench.params)
        start = time.perf_counter()
        result = run_episode(episode, policy, make_collider(episode), suite)
        if k == 0:
            continue  # warm-up
        wall += time.perf_counter() - start
        steps += result.steps
        outcomes.append(result.outcome)
    emit(
        {
            "bench": args.bench,
            "policy": args.policy,
            "resolution": args.resolution,
            "episodes": len(outcomes),
            "steps": steps,
            "wall_s": round(wall, 2),
            "steps_per_s": round(steps / wall, 2),
            "outcomes": {o: outcomes.count(o) for o in sorted(set(outcomes))},
            "threading_layer": numba.threading_layer(),
            "numba_threads": numba.get_num_threads(),
            "load_1min_start": round(load_start, 2),
            "load_1min_end": round(os.getloadavg()[0], 2),
        }
    )


if __name__ == "__main__":
    main()
