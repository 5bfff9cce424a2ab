"""Runtime throughput: environment steps per second (policy ``straight``), and ``song eval`` wall time.

    .venv/bin/python benchmarks/runtime.py [--bench DIR] [--gaussians 20000] [--avatars 5]

Without ``--bench`` it builds a synthetic 10 × 6 m room with ``--avatars`` pedestrians walking
across the robot's route, each posed with ``--gaussians`` points (rigidly, at its root), so the cost
of counting Gaussians inside the robot volume is the real one.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import emit  # noqa: E402

from song.config import RobotConfig  # noqa: E402
from song.datasets.bench import pedestrian_states  # noqa: E402
from song.runtime.avatars import AvatarCollider  # noqa: E402
from song.runtime.loop import EpisodeRunner  # noqa: E402
from song.runtime.policies import StraightPolicy  # noqa: E402
from tests.runtime.helpers import episode, track  # noqa: E402


def synthetic(n_avatars: int, n_gaussians: int):
    rng = np.random.default_rng(0)
    peds = [track(i, (2.0 + i, 5.5), (2.5 + i, 0.5), speed=0.6) for i in range(n_avatars)]
    ep = episode(start=(0.6, 3.0), goal=(9.4, 3.0), peds=peds)
    body = np.column_stack(
        [rng.normal(0, 0.12, n_gaussians), rng.normal(0, 0.18, n_gaussians), rng.uniform(0, 1.75, n_gaussians)]
    )

    def pose(index: int, t: float) -> np.ndarray:
        _, xy, _ = pedestrian_states([peds[index]], t)
        return body + np.array([xy[0, 0], xy[0, 1], 0.0])

    return ep, AvatarCollider(peds, pose)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--avatars", type=int, default=5)
    parser.add_argument("--gaussians", type=int, default=20_000)
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    ep, collider = synthetic(args.avatars, args.gaussians)
    policy = StraightPolicy()
    steps = 0
    start = time.perf_counter()
    outcomes = []
    for _ in range(args.episodes):
        runner = EpisodeRunner(ep, collider, RobotConfig(max_steps=200, eta_col=10**9))
        policy.reset(ep)
        while runner.outcome is None:
            runner.step(*policy.act(runner.observation()))
            steps += 1
        outcomes.append(runner.outcome)
    wall = time.perf_counter() - start
    emit(
        {
            "avatars": args.avatars,
            "gaussians_per_avatar": args.gaussians,
            "steps": steps,
            "steps_per_second": round(steps / wall, 1),
            "target_steps_per_second": 1000,
            "outcomes": sorted(set(outcomes)),
        }
    )


if __name__ == "__main__":
    main()
