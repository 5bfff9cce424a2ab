"""A* on boolean occupancy grids: 8-connected, Euclidean step costs (1, √2), no corner cutting.

The search is a textbook A* with the octile heuristic (consistent for these step costs, so the first
time the goal leaves the heap its cost is optimal) and a binary heap keyed by (f, cell index), which
makes ties, hence paths, deterministic. It runs as a numba-compiled kernel
(:mod:`song.geometry._astar_kernel`): a per-cell heap loop is what A* is, and in pure Python it is
~100× slower than the C++ ``pyastar2d``; numba brings it within the same range without a C extension
to build. Tests compare its lengths with networkx and with scipy's Dijkstra over the same graph.

With ``diagonal=False`` (4-connected unit steps, the problem ``pyastar2d`` solves) every key is an
integer, and a bucket queue replaces the heap (:func:`song.geometry._astar_kernel.search_kernel_4`).

Diagonal moves need both orthogonal neighbours free (as :func:`song.geometry.gridpath.grid_graph`), so
a path never squeezes between two blocked cells that touch at a corner.
"""

from __future__ import annotations

import numpy as np

from song.geometry._astar_kernel import SQRT2, STEPS, search_kernel, search_kernel_4

__all__ = ["SQRT2", "astar"]


def astar(
    free: np.ndarray, start: tuple[int, int], goal: tuple[int, int], limit: float = np.inf, diagonal: bool = True
) -> tuple[float, np.ndarray | None]:
    """Shortest path between two cells of a boolean grid.

    Args:
        free: (rows, cols) bool, True where the path may go.
        start: (row, col) start cell.
        goal: (row, col) goal cell.
        limit: give up once every open path is longer than this (cells); ``inf`` searches everything.
        diagonal: 8-connected with √2 diagonals (default, what grading uses); False for 4-connected
            unit steps (the problem ``pyastar2d`` solves without diagonals, for a like-for-like timing),
            searched with a bucket queue (:func:`song.geometry._astar_kernel.search_kernel_4`).

    Returns:
        ``(length in cells, cells (K, 2) int64 from start to goal)``, or ``(inf, None)`` when the goal
        is unreachable (or farther than ``limit``), or either end is blocked.
    """
    free = np.ascontiguousarray(free, dtype=np.uint8)
    rows, cols = free.shape
    for cell in (start, goal):
        if not (0 <= cell[0] < rows and 0 <= cell[1] < cols) or not free[cell]:
            return np.inf, None
    s, t = start[0] * cols + start[1], goal[0] * cols + goal[1]
    if diagonal:
        length, nodes = search_kernel(free, s, t, float(limit), STEPS, diagonal)
    else:  # unit steps: integer keys, a bucket queue instead of the heap
        length, nodes = search_kernel_4(free, s, t, float(limit))
    if not np.isfinite(length):
        return np.inf, None
    return float(length), np.column_stack([nodes // cols, nodes % cols])
