"""Compiled (numba) A* search for :mod:`song.geometry.astar`.

A per-cell heap loop is what A* is; in pure Python it is ~100x slower than the C++ ``pyastar2d``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

SQRT2 = math.sqrt(2.0)
STEPS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)], dtype=np.int64)


def _before(f1: float, h1: float, v1: int, f2: float, h2: float, v2: int) -> bool:
    """Heap order: smaller f, then smaller h (deeper nodes first: far fewer ties expanded), then cell."""
    if f1 != f2:
        return f1 < f2
    if h1 != h2:
        return h1 < h2
    return v1 <= v2


def _push(heap: np.ndarray, cells: np.ndarray, size: int, f: float, h: float, v: int):
    """Binary min-heap push; ``heap`` rows are (f, h), ``cells`` the cell ids (arrays grown by doubling)."""
    if size == len(cells):
        heap = np.concatenate((heap, np.empty_like(heap)))
        cells = np.concatenate((cells, np.empty_like(cells)))
    i = size
    while i > 0:
        up = (i - 1) >> 1
        if _before(heap[up, 0], heap[up, 1], cells[up], f, h, v):
            break
        heap[i, 0], heap[i, 1], cells[i] = heap[up, 0], heap[up, 1], cells[up]
        i = up
    heap[i, 0], heap[i, 1], cells[i] = f, h, v
    return heap, cells, size + 1


def _pop(heap: np.ndarray, cells: np.ndarray, size: int):
    """Pop the first entry; returns (f, cell, new size)."""
    top_f, top_v = heap[0, 0], cells[0]
    size -= 1
    f, h, v = heap[size, 0], heap[size, 1], cells[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _before(
            heap[right, 0], heap[right, 1], cells[right], heap[child, 0], heap[child, 1], cells[child]
        ):
            child = right
        if _before(f, h, v, heap[child, 0], heap[child, 1], cells[child]):
            break
        heap[i, 0], heap[i, 1], cells[i] = heap[child, 0], heap[child, 1], cells[child]
        i = child
    if size > 0:
        heap[i, 0], heap[i, 1], cells[i] = f, h, v
    return top_f, top_v, size


def _heuristic(dr: int, dc: int, diagonal: bool) -> float:
    """Octile distance (8-connected, √2 diagonals) or Manhattan distance (4-connected), in cells."""
    if diagonal:
        return float(dr + dc) + (SQRT2 - 2.0) * min(dr, dc)
    return float(dr + dc)


def _search(
    free: np.ndarray, start: int, goal: int, limit: float, steps: np.ndarray, diagonal: bool
) -> tuple[float, np.ndarray]:
    """Kernel: returns (cost in cells or inf, parent array). ``free`` is a uint8 grid (rows, cols)."""
    rows, cols = free.shape
    n = rows * cols
    flat = free.ravel()
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    gr, gc = goal // cols, goal % cols
    g[start] = 0.0
    heap = np.empty((1024, 2))
    cells = np.empty(1024, dtype=np.int64)
    sr, sc = start // cols, start % cols
    dr0, dc0 = abs(sr - gr), abs(sc - gc)
    h0 = _heuristic(dr0, dc0, diagonal)
    heap, cells, size = _push(heap, cells, 0, h0, h0, start)
    while size > 0:
        f, u, size = _pop(heap, cells, size)
        if u == goal:
            return g[u], parent
        r, c = u // cols, u % cols
        dr_goal, dc_goal = abs(r - gr), abs(c - gc)
        if f > g[u] + _heuristic(dr_goal, dc_goal, diagonal) + 1e-9:
            continue  # a stale entry (the cell was reached more cheaply since)
        if g[u] > limit:
            break
        for k in range(8 if diagonal else 4):
            dr, dc = steps[k, 0], steps[k, 1]
            nr, nc = r + dr, c + dc
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                continue
            v = nr * cols + nc
            if flat[v] == 0:
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
                h = _heuristic(ar, ac, diagonal)
                heap, cells, size = _push(heap, cells, size, candidate + h, h, v)
    return np.inf, parent


_before = numba.njit(cache=True, inline="always")(_before)
_heuristic = numba.njit(cache=True, inline="always")(_heuristic)
_push = numba.njit(cache=True, nogil=True)(_push)
_pop = numba.njit(cache=True, nogil=True)(_pop)
search_kernel = numba.njit(cache=True, nogil=True)(_search)
