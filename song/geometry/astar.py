"""A* on boolean occupancy grids: 8-connected, Euclidean step costs (1, √2), no corner cutting.

The search is a textbook A* with the octile heuristic (consistent for these step costs, so the first
time the goal leaves the heap its cost is optimal) and a binary heap keyed by (f, cell index), which
makes ties, hence paths, deterministic. It runs as a numba-compiled kernel: a per-cell heap loop is
what A* is, and in pure Python it is ~100× slower than the C++ ``pyastar2d``; numba brings it within
the same range without a C extension to build. Without numba, :func:`astar` falls back to scipy's
compiled Dijkstra over the same graph (``song.geometry.gridpath``): same lengths, slower.

Diagonal moves need both orthogonal neighbours free (as :func:`song.geometry.gridpath.grid_graph`), so
a path never squeezes between two blocked cells that touch at a corner.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

SQRT2 = math.sqrt(2.0)
_STEPS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)], dtype=np.int64)

try:  # numba is a dependency; the fallback keeps a broken/absent install usable
    import numba
except ImportError:  # pragma: no cover - exercised by the fallback test through HAVE_NUMBA
    numba = None
HAVE_NUMBA = numba is not None


def _search(free: np.ndarray, start: int, goal: int, limit: float, steps: np.ndarray) -> tuple[float, np.ndarray]:
    """Kernel: returns (cost in cells or inf, parent array). ``free`` is a flat uint8 grid (rows, cols)."""
    rows, cols = free.shape
    n = rows * cols
    flat = free.ravel()
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.uint8)
    gr, gc = goal // cols, goal % cols
    g[start] = 0.0
    sr, sc = start // cols, start % cols
    dr0, dc0 = abs(sr - gr), abs(sc - gc)
    heap = [(float(dr0 + dc0) + (SQRT2 - 2.0) * min(dr0, dc0), start)]
    while len(heap) > 0:
        f, u = heapq.heappop(heap)
        if closed[u]:
            continue
        if u == goal:
            return g[u], parent
        closed[u] = 1
        if g[u] > limit:
            break
        r, c = u // cols, u % cols
        for k in range(8):
            dr, dc = steps[k, 0], steps[k, 1]
            nr, nc = r + dr, c + dc
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                continue
            v = nr * cols + nc
            if flat[v] == 0 or closed[v]:
                continue
            if dr != 0 and dc != 0:
                if flat[r * cols + nc] == 0 or flat[nr * cols + c] == 0:
                    continue
                step = SQRT2
            else:
                step = 1.0
            candidate = g[u] + step
            if candidate < g[v]:
                g[v] = candidate
                parent[v] = u
                ar, ac = abs(nr - gr), abs(nc - gc)
                heapq.heappush(heap, (candidate + float(ar + ac) + (SQRT2 - 2.0) * min(ar, ac), v))
    return np.inf, parent


_kernel = numba.njit(cache=True, nogil=True)(_search) if HAVE_NUMBA else None


def astar(
    free: np.ndarray, start: tuple[int, int], goal: tuple[int, int], limit: float = np.inf
) -> tuple[float, np.ndarray | None]:
    """Shortest 8-connected path between two cells of a boolean grid.

    Args:
        free: (rows, cols) bool, True where the path may go.
        start, goal: (row, col) cells.
        limit: give up once every open path is longer than this (cells); ``inf`` searches everything.

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
    if _kernel is not None:
        length, parent = _kernel(free, s, t, float(limit), _STEPS)
    else:
        length, parent = _fallback(free, s, t, limit)
    if not np.isfinite(length):
        return np.inf, None
    chain = [t]
    while chain[-1] != s:
        chain.append(int(parent[chain[-1]]))
    nodes = np.array(chain[::-1], dtype=np.int64)
    return float(length), np.column_stack([nodes // cols, nodes % cols])


def _fallback(free: np.ndarray, start: int, goal: int, limit: float) -> tuple[float, np.ndarray]:
    """scipy Dijkstra over the same graph, returning a parent array over grid cells like the kernel."""
    from song.geometry.gridpath import distances_from, grid_graph

    cols = free.shape[1]
    graph = grid_graph(free.astype(bool))
    dist, pred = distances_from(graph, (start // cols, start % cols), with_path=True, limit=limit)
    node = graph.index[goal // cols, goal % cols]
    parent = np.full(free.size, -1, dtype=np.int64)
    ids = graph.cells[:, 0] * cols + graph.cells[:, 1]
    has = pred >= 0
    parent[ids[has]] = ids[pred[has]]
    return float(dist[node]), parent
