"""ORCA throughput: agent-steps per second, ours (the numba kernel) vs RVO2 (pyrvo), circle.

N agents on a circle walk to their antipodes (1–5 cm seeded start jitter) through the crowded centre;
both simulators run the same steps with the same parameters and the same preferred-velocity rule,
computed in numpy from each one's own positions. pyrvo has no batch API, so its figure includes the
per-agent get/set calls any Python caller makes; ``rvo2_do_step_only`` leaves them out.

.venv/bin/python benchmarks/orca.py [--quick] [--steps N]
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

PARAMS = OrcaParams(time_step=1 / 30, neighbor_dist=5.0, max_neighbors=10, time_horizon=5.0, time_horizon_obst=2.0)
RADIUS, SPEED = 0.25, 1.0


def circle(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal positions (n, 2), m: a circle 1.2 m of arc per agent (at least 4 m radius)."""
    rng = np.random.default_rng(n)
    a = 2 * np.pi * np.arange(n) / n
    r = max(4.0, n * 1.2 / (2 * np.pi))
    jitter_dir = rng.uniform(0, 2 * np.pi, n)
    jitter = rng.uniform(0.01, 0.05, n)[:, None] * np.column_stack([np.cos(jitter_dir), np.sin(jitter_dir)])
    start = r * np.column_stack([np.cos(a), np.sin(a)]) + jitter
    return start, -start


def pref_velocity(pos: np.ndarray, goal: np.ndarray) -> np.ndarray:
    to_goal = goal - pos
    dist = np.linalg.norm(to_goal, axis=1, keepdims=True)
    return to_goal / PARAMS.time_step * np.minimum(1.0, SPEED * PARAMS.time_step / np.maximum(dist, 1e-12))


def ours(n: int, steps: int, step=orca_step) -> dict:
    pos, goal = circle(n)
    vel = np.zeros((n, 2))
    radii, speeds = np.full(n, RADIUS), np.full(n, SPEED)
    t = time.perf_counter()
    for _ in range(steps):
        vel = step(pos, vel, pref_velocity(pos, goal), radii, speeds, None, PARAMS)
        pos = pos + vel * PARAMS.time_step
    elapsed = time.perf_counter() - t
    return {"agent_steps_s": n * steps / elapsed, "arrived": int((np.linalg.norm(pos - goal, axis=1) < 0.01).sum())}


def rvo2(n: int, steps: int) -> dict:
    import pyrvo

    pos, goal = circle(n)
    sim = pyrvo.RVOSimulator(
        PARAMS.time_step,
        PARAMS.neighbor_dist,
        PARAMS.max_neighbors,
        PARAMS.time_horizon,
        PARAMS.time_horizon_obst,
        RADIUS,
        SPEED,
    )
    for p in pos:
        sim.add_agent((float(p[0]), float(p[1])))
    in_step = 0.0
    t = time.perf_counter()
    for _ in range(steps):
        pos = np.array([sim.get_agent_position(i).to_tuple() for i in range(n)])
        for i, v in enumerate(pref_velocity(pos, goal).tolist()):
            sim.set_agent_pref_velocity(i, v)
        s = time.perf_counter()
        sim.do_step()
        in_step += time.perf_counter() - s
    elapsed = time.perf_counter() - t
    pos = np.array([sim.get_agent_position(i).to_tuple() for i in range(n)])
    return {
        "agent_steps_s": n * steps / elapsed,
        "do_step_only_agent_steps_s": n * steps / in_step,
        "arrived": int((np.linalg.norm(pos - goal, axis=1) < 0.01).sum()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="150 steps per size (the approach, not the crossing)")
    parser.add_argument("--steps", type=int, default=0, help="steps per size (default: until all have crossed)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 64, 256])
    args = parser.parse_args()
    rows = {}
    for n in args.sizes:
        radius = max(4.0, n * 1.2 / (2 * np.pi))
        steps = args.steps or (150 if args.quick else int(2.6 * radius / SPEED / PARAMS.time_step))
        ours(4, 2)  # compile (or load the cached kernel) outside the timing
        a, b = ours(n, steps), rvo2(n, steps)
        rows[str(n)] = {
            "steps": steps,
            "ours_agent_steps_s": round(a["agent_steps_s"]),
            "rvo2_agent_steps_s": round(b["agent_steps_s"]),
            "rvo2_do_step_only_agent_steps_s": round(b["do_step_only_agent_steps_s"]),
            "ratio": round(a["agent_steps_s"] / b["agent_steps_s"], 3),
            "ratio_vs_do_step_only": round(a["agent_steps_s"] / b["do_step_only_agent_steps_s"], 3),
            "arrived_ours": a["arrived"],
            "arrived_rvo2": b["arrived"],
        }
    emit(
        {
            "scenario": "circle to antipodes, 1.2 m of arc per agent, 1-5 cm jitter",
            "params": {**PARAMS.__dict__, "radius": RADIUS, "max_speed": SPEED},
            "agents": rows,
            "targets": {"ratio_256": 1.0, "ratio_16": 0.3},
        }
    )


if __name__ == "__main__":
    main()
