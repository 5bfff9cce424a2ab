"""ORCA throughput: agent-steps per second, ours (vectorised numpy) vs RVO2 (pyrvo), circle scenario.

.venv/bin/python benchmarks/orca.py [--steps 200]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.pipeline.crowd.orca import OrcaParams, orca_step  # noqa: E402

PARAMS = OrcaParams(time_step=1 / 30, neighbor_dist=5.0, max_neighbors=10, time_horizon=5.0)


def circle(n: int) -> tuple[np.ndarray, np.ndarray]:
    a = 2 * np.pi * np.arange(n) / n
    r = max(4.0, n * 0.6 / np.pi)
    start = r * np.column_stack([np.cos(a), np.sin(a)]) + np.random.default_rng(n).uniform(-0.03, 0.03, (n, 2))
    return start, -start


def ours(n: int, steps: int) -> float:
    pos, goal = circle(n)
    vel = np.zeros((n, 2))
    t = time.perf_counter()
    for _ in range(steps):
        to = goal - pos
        d = np.linalg.norm(to, axis=1, keepdims=True)
        pref = np.where(d > 1e-9, to / np.maximum(d, 1e-9), 0.0) * np.minimum(1.0, d / PARAMS.time_step)
        vel = orca_step(pos, vel, pref, np.full(n, 0.25), np.full(n, 1.0), PARAMS)
        pos = pos + vel * PARAMS.time_step
    return n * steps / (time.perf_counter() - t)


def rvo2(n: int, steps: int) -> float:
    import pyrvo

    pos, goal = circle(n)
    sim = pyrvo.RVOSimulator(
        PARAMS.time_step, PARAMS.neighbor_dist, PARAMS.max_neighbors, PARAMS.time_horizon, 1.0, 0.25, 1.0
    )
    for p in pos:
        sim.add_agent((float(p[0]), float(p[1])))
    t = time.perf_counter()
    for _ in range(steps):
        for i in range(n):
            p = np.array(sim.get_agent_position(i).to_tuple())
            to = goal[i] - p
            d = np.linalg.norm(to)
            v = to / d * min(1.0, d / PARAMS.time_step) if d > 1e-9 else np.zeros(2)
            sim.set_agent_pref_velocity(i, (float(v[0]), float(v[1])))
        sim.do_step()
    return n * steps / (time.perf_counter() - t)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    rows = {}
    for n in (16, 64, 256):
        a, b = ours(n, args.steps), rvo2(n, args.steps)
        rows[str(n)] = {"ours_agent_steps_s": round(a), "rvo2_agent_steps_s": round(b), "ratio": round(a / b, 3)}
    emit(
        {
            "scenario": "circle to antipodes",
            "steps": args.steps,
            "agents": rows,
            "targets": {"ratio_256": 1.0, "ratio_16": 0.3},
        }
    )


if __name__ == "__main__":
    main()
