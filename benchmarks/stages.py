"""Per-scene stage timings on the sample scenes (intents, crowd) and A* vs pyastar2d.

.venv/bin/python benchmarks/stages.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import SongConfig  # noqa: E402
from song.datasets.scenes import find_scene_packages, load_scene_package  # noqa: E402
from song.geometry.gridpath import distances_from, grid_graph, path_cells  # noqa: E402
from song.pipeline.crowd.simulate import plan_crowd  # noqa: E402
from song.pipeline.intents import generate_intents  # noqa: E402
from song.pipeline.intents.navigation import walkable  # noqa: E402


def astar_vs_pyastar2d(n: int = 400) -> dict:
    import pyastar2d

    rng = np.random.default_rng(0)
    free = rng.random((n, n)) > 0.2
    free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = True
    start, goal = (0, 0), (n - 1, n - 1)
    t = time.perf_counter()
    graph = grid_graph(free)
    build = time.perf_counter() - t
    t = time.perf_counter()
    dist, pred = distances_from(graph, start, with_path=True)
    cells = path_cells(graph, dist, pred, goal)
    ours = time.perf_counter() - t
    weights = np.where(free, 1.0, np.inf).astype(np.float32)
    t = time.perf_counter()
    path = pyastar2d.astar_path(weights, start, goal, allow_diagonal=True)
    theirs = time.perf_counter() - t
    ours_len = float(dist[graph.index[goal]])
    steps = np.diff(path, axis=0)
    theirs_len = float(np.linalg.norm(steps, axis=1).sum())
    return {
        "grid": n,
        "ours_query_s": round(ours, 4),
        "ours_graph_build_s": round(build, 4),
        "pyastar2d_s": round(theirs, 4),
        "ratio": round(ours / theirs, 2),
        "ours_length_cells": round(ours_len, 3),
        "pyastar2d_length_cells": round(theirs_len, 3),
        "note": "pyastar2d lets diagonal moves cut corners and uses unit diagonal costs in its search; lengths differ",
        "path_cells": int(len(cells)),
    }


def main() -> None:
    config = SongConfig()
    intents_ms, crowd_s, peds = [], [], []
    for root in find_scene_packages(ROOT / "datasets" / "sample_scenes"):
        package = load_scene_package(root)
        t = time.perf_counter()
        intents = generate_intents(package, config, np.random.default_rng(0))
        intents_ms.append(1000 * (time.perf_counter() - t))
        t = time.perf_counter()
        plan_crowd(
            intents.intents, walkable(package, config.crowd.agent_radius_m), config.crowd, np.random.default_rng(0)
        )
        crowd_s.append(time.perf_counter() - t)
        peds.append(len(intents.intents))
    emit(
        {
            "scenes": len(crowd_s),
            "intents_ms_median": round(float(np.median(intents_ms)), 1),
            "crowd_s_median": round(float(np.median(crowd_s)), 3),
            "crowd_s_max": round(float(np.max(crowd_s)), 3),
            "pedestrians_per_scene_median": float(np.median(peds)),
            "targets": {"intents_ms_median": 50, "crowd_s_median": 0.5},
            "astar": astar_vs_pyastar2d(),
        }
    )


if __name__ == "__main__":
    main()
