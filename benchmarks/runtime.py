"""Runtime throughput: environment steps per second (policy ``straight``), and ``song eval`` wall time.

    .venv/bin/python benchmarks/runtime.py [--gaussians 20000] [--avatars 5] [--episodes 20]

It builds a synthetic 10 × 6 m room with ``--avatars`` pedestrians walking across the robot's route,
each a ``--gaussians`` avatar posed by LBS from its motion cache (procedural gait), exactly as the
runtime poses release avatars: only those within reach of the robot are posed at each step.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import emit  # noqa: E402

from song.config import MotionConfig, RobotConfig  # noqa: E402
from song.datasets.avatars.cache import MotionCache, PosedAvatar  # noqa: E402
from song.datasets.bench.types import RuntimeParams  # noqa: E402
from song.pipeline.motion import synthesize_motions  # noqa: E402
from song.pipeline.motion.types import Trajectory  # noqa: E402
from song.runtime.avatars import AvatarCollider  # noqa: E402
from song.runtime.loop import EpisodeRunner  # noqa: E402
from song.runtime.policies import StraightPolicy  # noqa: E402
from tests.avatar_factory import capsule_avatar  # noqa: E402
from tests.runtime.helpers import episode, track  # noqa: E402


def synthetic(n_avatars: int, n_gaussians: int):
    """A room with pedestrians crossing the robot's route, each a real LBS-posed avatar (gait + cache)."""
    peds = [track(i, (2.0 + i, 5.5), (2.5 + i, 0.5), speed=0.6) for i in range(n_avatars)]
    ep = episode(start=(0.6, 3.0), goal=(9.4, 3.0), peds=peds)
    trajectories = [
        Trajectory(p.ped_id, p.t, np.round(p.t * 30).astype(np.int32), p.xy, p.yaw, np.full(len(p.t), 0.6))
        for p in peds
    ]
    motions = synthesize_motions(trajectories, [""] * n_avatars, list(range(n_avatars)), MotionConfig())
    avatars = []
    for i, (motion, _) in enumerate(motions):
        asset = capsule_avatar(f"a{i}", n=n_gaussians, height=float(motion.height_m), seed=i)
        frame0 = int(trajectories[i].frame[0])
        cache = MotionCache(
            motion.root_pos.astype(np.float32),
            motion.local_quats.astype(np.float32),
            asset.rest_joints,
            30.0,
            frame0,
            {"scale": 1.0},
        )
        avatars.append(PosedAvatar.load(asset, cache))
    return ep, AvatarCollider(peds, lambda index, t: avatars[index].means_at(t))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--avatars", type=int, default=5)
    parser.add_argument("--gaussians", type=int, default=20_000)
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    ep, collider = synthetic(args.avatars, args.gaussians)
    ep = dataclasses.replace(ep, params=RuntimeParams(robot=RobotConfig(max_steps=200, eta_col=10**9)))
    policy = StraightPolicy()
    steps = 0
    start = time.perf_counter()
    outcomes = []
    for _ in range(args.episodes):
        runner = EpisodeRunner(ep, collider)
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
