"""Grading figures (issue #7), one JSON object.

.venv/bin/python benchmarks/grading.py [--quick] [--run RUN --episodes N --workers 2]

- A* per query on a 400×400 random grid (20 % blocked, corner to corner) against ``pyastar2d`` (C++)
  in the same process. Like for like on the 4-connected problem (unit steps, the problem pyastar2d
  solves without diagonals): both lengths and the time ratio. Also our 8-connected √2-cost search
  (what grading uses), which pyastar2d cannot express (its diagonal steps cost 1), so no ratio.
- A* on serpentine grids (400² and 800²: walls every 4 rows, a gap at alternate ends), where the
  search must explore most of the grid: 4-connected, ours against pyastar2d interleaved (median of
  repeats), both lengths.
- With ``--run``: ``grade_run`` wall time for N episodes on that run (e.g. the 500-scene run that
  ``benchmarks/e2e.py --out DIR`` leaves in DIR/run).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.geometry.astar import astar  # noqa: E402


def _best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def astar_figures(n: int, repeats: int) -> dict:
    import pyastar2d

    rng = np.random.default_rng(0)
    free = rng.random((n, n)) > 0.2
    free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = True
    weights = np.where(free, 1.0, np.inf).astype(np.float32)
    start, goal = (0, 0), (n - 1, n - 1)
    astar(free, start, goal)  # compile (or load the cached kernel) outside the timing
    out = {"grid": n}
    ours_len, _ = astar(free, start, goal, diagonal=False)
    theirs_path = pyastar2d.astar_path(weights, start, goal, allow_diagonal=False)
    ours = _best_of(lambda: astar(free, start, goal, diagonal=False), repeats)
    theirs = _best_of(lambda: pyastar2d.astar_path(weights, start, goal, allow_diagonal=False), repeats)
    out["4_connected"] = {
        "ours_ms": round(1000 * ours, 2),
        "pyastar2d_ms": round(1000 * theirs, 2),
        "ratio": round(ours / theirs, 2),
        "ours_length": ours_len,
        "pyastar2d_length": float(len(theirs_path) - 1),
    }
    length8, _ = astar(free, start, goal)
    out["8_connected_sqrt2"] = {"ours_ms": round(1000 * _best_of(lambda: astar(free, start, goal), repeats), 2)}
    out["8_connected_sqrt2"]["ours_length"] = round(length8, 4)
    return out


def serpentine(n: int) -> np.ndarray:
    """(n, n) free mask: a wall every 4th row, open at alternate ends (one long winding corridor)."""
    free = np.ones((n, n), dtype=bool)
    for k, r in enumerate(range(3, n - 1, 4)):
        free[r, :] = False
        gap = slice(n - 2, n) if k % 2 == 0 else slice(0, 2)
        free[r, gap] = True
    return free


def serpentine_figures(n: int, repeats: int) -> dict:
    import pyastar2d

    free = serpentine(n)
    weights = np.where(free, 1.0, np.inf).astype(np.float32)
    start, goal = (0, 0), (n - 1, 0)
    astar(free, start, goal, diagonal=False)
    ours, theirs = [], []
    for _ in range(repeats):  # interleaved: the machine's load hits both alike
        t0 = time.perf_counter()
        ours_len, _ = astar(free, start, goal, diagonal=False)
        t1 = time.perf_counter()
        path = pyastar2d.astar_path(weights, start, goal, allow_diagonal=False)
        t2 = time.perf_counter()
        ours.append(t1 - t0)
        theirs.append(t2 - t1)
    return {
        "grid": n,
        "ours_ms": round(1000 * float(np.median(ours)), 2),
        "pyastar2d_ms": round(1000 * float(np.median(theirs)), 2),
        "speed_vs_pyastar2d": round(float(np.median(theirs) / np.median(ours)), 2),
        "ours_length": ours_len,
        "pyastar2d_length": float(len(path) - 1),
    }


def grading_figures(run: Path, episodes: int, workers: int) -> dict:
    from song.pipeline.grading import grade_run

    start = time.perf_counter()
    grade_run(run, n_episodes=episodes, workers=workers)
    return {"run": str(run), "episodes": episodes, "workers": workers, "seconds": round(time.perf_counter() - start, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--run", type=Path, default=None, help="a synthesised run to grade (timed)")
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    repeats = 3 if args.quick else 15
    result = {"astar_400": astar_figures(400, repeats)}
    result["serpentine"] = [serpentine_figures(n, repeats) for n in (400, 800)]
    result["targets"] = {"astar_4_connected_ratio": 2.0, "serpentine_speed_vs_pyastar2d": 1.0, "grading_500_s": 30.0}
    if args.run:
        result["grading"] = grading_figures(args.run, args.episodes, args.workers)
    emit(result)


if __name__ == "__main__":
    main()
