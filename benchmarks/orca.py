"""ORCA throughput: agent-steps per second, ours (the numba kernel) vs RVO2 (pyrvo), circle.

N agents on a circle walk to their antipodes (1–5 cm seeded start jitter) through the crowded centre;
both simulators run the same steps with the same parameters and the same preferred-velocity rule,
computed in numpy from each one's own positions. With ``--obstacles`` both also get four square pillars
(side 1 m + N/256 m) around the centre. Headline: ``ours_step_only`` (time inside ``orca_step``, our
whole step including its Python wrapper) against ``rvo2_do_step_only`` (time inside pyrvo's
``do_step``); the loop figures add the preferred velocities and, for pyrvo, the per-agent get/set
calls a Python caller needs (it has no batch API). The two simulators run interleaved per size.

.venv/bin/python benchmarks/orca.py [--quick] [--steps N] [--sizes 16 256 1024] [--obstacles]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.pipeline.crowd.orca import OrcaParams, build_obstacles, orca_step  # noqa: E402

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


def pillars(n: int) -> list[np.ndarray]:
    """Four counter-clockwise squares around the centre of the circle of ``n`` agents."""
    radius, side = max(4.0, n * 1.2 / (2 * np.pi)), 1.0 + n / 256
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * side / 2
    return [square + radius / 3 * np.array([np.cos(a), np.sin(a)]) for a in np.pi / 4 + np.arange(4) * np.pi / 2]


def ours(n: int, steps: int, polygons=(), step=orca_step) -> dict:
    pos, goal = circle(n)
    vel = np.zeros((n, 2))
    radii, speeds = np.full(n, RADIUS), np.full(n, SPEED)
    obstacles = build_obstacles(list(polygons)) if len(polygons) else None
    in_step = 0.0
    t = time.perf_counter()
    for _ in range(steps):
        pref = pref_velocity(pos, goal)
        s = time.perf_counter()
        vel = step(pos, vel, pref, radii, speeds, obstacles, PARAMS)
        in_step += time.perf_counter() - s
        pos = pos + vel * PARAMS.time_step
    elapsed = time.perf_counter() - t
    return {
        "agent_steps_s": n * steps / elapsed,
        "step_only_agent_steps_s": n * steps / in_step,
        "arrived": int((np.linalg.norm(pos - goal, axis=1) < 0.01).sum()),
    }


def rvo2(n: int, steps: int, polygons=()) -> dict:
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
    for poly in polygons:
        sim.add_obstacle([(float(x), float(y)) for x, y in poly])
    if len(polygons):
        sim.process_obstacles()
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
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 256, 1024])
    parser.add_argument("--obstacles", action="store_true", help="four square pillars around the centre")
    args = parser.parse_args()
    rows = {}
    ours(4, 2, pillars(4))  # compile (or load the cached kernel) outside the timing
    for n in args.sizes:
        radius = max(4.0, n * 1.2 / (2 * np.pi))
        steps = args.steps or (150 if args.quick else int(2.6 * radius / SPEED / PARAMS.time_step))
        polygons = pillars(n) if args.obstacles else ()
        a, b = ours(n, steps, polygons), rvo2(n, steps, polygons)
        rows[str(n)] = {
            "steps": steps,
            "ours_step_only_agent_steps_s": round(a["step_only_agent_steps_s"]),
            "rvo2_do_step_only_agent_steps_s": round(b["do_step_only_agent_steps_s"]),
            "ratio_step_only": round(a["step_only_agent_steps_s"] / b["do_step_only_agent_steps_s"], 3),
            "ours_loop_agent_steps_s": round(a["agent_steps_s"]),
            "rvo2_loop_agent_steps_s": round(b["agent_steps_s"]),
            "ratio_loop": round(a["agent_steps_s"] / b["agent_steps_s"], 3),
            "arrived_ours": a["arrived"],
            "arrived_rvo2": b["arrived"],
        }
    emit(
        {
            "scenario": "circle to antipodes, 1.2 m of arc per agent, 1-5 cm jitter"
            + (", four square pillars" if args.obstacles else ""),
            "params": {**PARAMS.__dict__, "radius": RADIUS, "max_speed": SPEED},
            "agents": rows,
            "targets": {"ratio_step_only": 1.0},
        }
    )


if __name__ == "__main__":
    main()
