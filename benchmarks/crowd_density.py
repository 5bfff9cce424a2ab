"""Crowd planning cost against density in a generated lobby, one JSON object.

.venv/bin/python benchmarks/crowd_density.py [--counts 8 16 32 64] [--set crowd.KEY=VALUE ...]

The scene: the procedural lobby ``lobby_0002`` (seed 7, the one ``benchmarks/render.py`` uses; its
navmesh at r = 0.25 m is reported). For each count N we draw N synthetic single-leg intents on the
mesh (seeded): starts and goals at least 0.8 m from each other's, paths 5–25 m long, speeds uniform
0.5–1.0 m/s (the paper's profile), departures uniform over the first 20 s. The crowd planner
(:func:`song.pipeline.crowd.simulate.plan_crowd`) runs on them with the default crowd settings; we
report wall and CPU seconds (the process's, all threads), the simulated seconds, the pedestrians by outcome (arrived, gave up, still under
way at the end) and the cost ratio of the largest count to the smallest. Beside it, the cost per
pedestrian-second simulated (everyone is simulated from the first frame to the last) and its ratio:
near 1 when the planner scales linearly, whatever the jams do to the length of the run.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import dither_summary, emit, give_up_dither  # noqa: E402

from song.config import SongConfig, parse_assignments  # noqa: E402
from song.datasets.run.intents import Intent, Provenance  # noqa: E402
from song.datasets.scenes import load_scene_package  # noqa: E402
from song.datasets.scenes.generate import generate_scene  # noqa: E402
from song.geometry.navmesh import Navmesh  # noqa: E402
from song.pipeline.crowd.avoidance import make_avoidance  # noqa: E402
from song.pipeline.crowd.navmesh import scene_navmesh  # noqa: E402
from song.pipeline.crowd.simulate import plan_crowd  # noqa: E402
from song.util import derive_rng  # noqa: E402

SPACING_M, MIN_PATH_M, MAX_PATH_M, DEPART_S = 0.8, 5.0, 25.0, 20.0
OUTCOMES = ("arrived", "gave_up", "timeout", "removed")


def synthetic_intents(mesh: Navmesh, count: int, seed: int) -> list[Intent]:
    """``count`` single-leg intents with spaced starts and goals on ``mesh`` (see the module doc)."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    starts: list[np.ndarray] = []
    goals: list[np.ndarray] = []
    intents: list[Intent] = []
    for _ in range(200 * count):
        if len(intents) == count:
            break
        a, b = rng.uniform(lo, hi, (2, 2))
        if not mesh.contains(np.stack([a, b])).all():
            continue
        if any(np.hypot(*(a - s)) < SPACING_M for s in starts) or any(np.hypot(*(b - g)) < SPACING_M for g in goals):
            continue
        res = mesh.find_path(a, b, max_snap=0.0, allow_partial=False)
        length = float(np.sum(np.hypot(*np.diff(res.points, axis=0).T))) if res.status == "ok" else 0.0
        if not MIN_PATH_M <= length <= MAX_PATH_M:
            continue
        starts.append(a)
        goals.append(b)
        intents.append(
            Intent(
                id=len(intents),
                activity="walk",
                start_object="start",
                goal_object="goal",
                start_xy=(float(a[0]), float(a[1])),
                goal_xy=(float(b[0]), float(b[1])),
                speed=float(rng.uniform(0.5, 1.0)),
                depart_time=float(rng.uniform(0.0, DEPART_S)),
                provenance=Provenance(provider="offline", model="benchmark"),
            )
        )
    if len(intents) < count:
        raise SystemExit(f"only {len(intents)} of {count} spaced intents fit the lobby")
    return intents


def timed(intents, mesh, config) -> tuple[float, float, dict]:
    """Wall and CPU seconds of one crowd plan, and its outcome counts (and the give-up dither)."""
    cfg = config.crowd
    start, cpu = time.perf_counter(), time.process_time()
    plan = plan_crowd(intents, mesh, make_avoidance(mesh, cfg), cfg, derive_rng(0, "lobby", "crowd"))
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    counts = {kind: sum(v["status"] == kind for v in plan.status.values()) for kind in OUTCOMES}
    simulated = round((plan.xy.shape[1] - 1) / plan.fps, 1)
    return (
        seconds,
        cpu,
        {
            "simulated_s": simulated,
            **counts,
            **dither_summary(give_up_dither(plan.xy, plan.ped_ids, plan.status, intents, mesh, plan.fps)),
        },
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument(
        "--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="config override (as `song --set`)"
    )
    args = parser.parse_args()
    config = SongConfig(**parse_assignments(args.set))
    with tempfile.TemporaryDirectory() as tmp:
        package = load_scene_package(generate_scene("lobby_0002", "lobby", 7, Path(tmp), splat=False))
    mesh = scene_navmesh(package, config.crowd.agent_radius_m, config.crowd.contour_error_m)
    timed(synthetic_intents(mesh, 4, 99), mesh, config)  # first-use compilation outside the timings
    rows = []
    for count in args.counts:
        seconds, cpu, outcomes = timed(synthetic_intents(mesh, count, count), mesh, config)
        per = seconds / (count * outcomes["simulated_s"]) * 1000.0  # everyone is simulated for the whole run
        rows.append(
            {
                "pedestrians": count,
                "seconds": round(seconds, 2),
                "cpu_seconds": round(cpu, 2),
                "ms_per_pedestrian_s": round(per, 3),
                **outcomes,
            }
        )
    emit(
        {
            "scene": "lobby_0002 (seed 7)",
            "navmesh_m2": round(mesh.area, 1),
            "runs": rows,
            "settings": args.set,
            "cost_ratio_largest_to_smallest": round(rows[-1]["seconds"] / rows[0]["seconds"], 1),
            "cpu_ratio_largest_to_smallest": round(rows[-1]["cpu_seconds"] / rows[0]["cpu_seconds"], 1),
            "per_pedestrian_s_ratio_largest_to_smallest": round(
                rows[-1]["ms_per_pedestrian_s"] / rows[0]["ms_per_pedestrian_s"], 2
            ),
            "target_ratio_64_to_8": 10.0,
        }
    )


if __name__ == "__main__":
    main()
