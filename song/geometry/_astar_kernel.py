"""Compiled (numba) A* search for :mod:`song.geometry.astar`, and the binary heap it shares.

A per-cell heap loop is what A* is; in pure Python it is ~100x slower than the C++ ``pyastar2d``.
The loop is written for the compiler: the grid is padded with a blocked border (no bounds tests),
neighbours are precomputed flat offsets, a closed flag replaces the stale-entry test, the heap is one
contiguous array keyed by a single float, neighbours whose key does not exceed the expanded cell's
bypass the heap on a stack (with a consistent heuristic they are the next to expand anyway: their f
equals the current minimum, and nothing cheaper is left), and the path is traced back inside the kernel.
"""

from __future__ import annotations

import math

import numba
import numpy as np

SQRT2 = math.sqrt(2.0)
STEPS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)], dtype=np.int64)


TIE = 1e-9  # key = f + TIE * h: equal f pops the deeper node first (far fewer ties expanded on open grids)


@numba.njit(cache=True)
def heap_push(heap: np.ndarray, size: int, key: float, v: int) -> int:
    """Insert (key, v) into the binary min-heap ``heap`` (cap, 2) of ``size`` entries; returns the new size.

    One contiguous array of (key, id as float) rows and one comparison per level: the heap is most
    of A*'s time, and three arrays with a three-way comparison made it ~1.5× slower.
    """
    i = size
    while i > 0:
        up = (i - 1) >> 1
        if heap[up, 0] <= key:
            break
        heap[i, 0], heap[i, 1] = heap[up, 0], heap[up, 1]
        i = up
    heap[i, 0], heap[i, 1] = key, v
    return size + 1


@numba.njit(cache=True)
def heap_pop(heap: np.ndarray, size: int):
    """Remove the first entry; returns ``(key, id, new size)``."""
    top_key, top_v = heap[0, 0], heap[0, 1]
    size -= 1
    key, v = heap[size, 0], heap[size, 1]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and heap[child + 1, 0] < heap[child, 0]:
            child += 1
        if key <= heap[child, 0]:
            break
        heap[i, 0], heap[i, 1] = heap[child, 0], heap[child, 1]
        i = child
    if size > 0:
        heap[i, 0], heap[i, 1] = key, v
    return top_key, int(top_v), size


@numba.njit(cache=True)
def heap_reserve(heap: np.ndarray, size: int) -> np.ndarray:
    """The heap, doubled in capacity when it is full."""
    if size < len(heap):
        return heap
    return np.concatenate((heap, np.empty_like(heap)))


@numba.njit(cache=True, inline="always")
def _heuristic(dr: int, dc: int, diagonal: bool) -> float:
    """Octile distance (8-connected, √2 diagonals) or Manhattan distance (4-connected), in cells."""
    if diagonal:
        return float(dr + dc) + (SQRT2 - 2.0) * min(dr, dc)
    return float(dr + dc)


@numba.njit(cache=True, nogil=True)
def search_kernel(free: np.ndarray, start: int, goal: int, limit: float, steps: np.ndarray, diagonal: bool):
    """A* from ``start`` to ``goal`` (flat ids of the (rows, cols) uint8 grid ``free``).

    Returns:
        ``(cost in cells or inf, path (K,) int64 flat ids from start to goal; empty when none)``.
    """
    rows, cols = free.shape
    width = cols + 2  # padded with a blocked border
    pad = np.zeros((rows + 2) * width, dtype=np.uint8)
    for r in range(rows):
        for c in range(cols):
            pad[(r + 1) * width + c + 1] = free[r, c]
    n_steps = 8 if diagonal else 4
    offset = np.empty(n_steps, dtype=np.int64)
    side_r = np.empty(n_steps, dtype=np.int64)
    side_c = np.empty(n_steps, dtype=np.int64)
    cost = np.empty(n_steps)
    for k in range(n_steps):
        dr, dc = steps[k, 0], steps[k, 1]
        offset[k] = dr * width + dc
        side_r[k], side_c[k] = dr * width, dc  # the two orthogonal cells a diagonal step passes
        cost[k] = SQRT2 if dr != 0 and dc != 0 else 1.0
    s = (start // cols + 1) * width + start % cols + 1
    t = (goal // cols + 1) * width + goal % cols + 1
    n = len(pad)
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.uint8)
    gr, gc = t // width, t % width
    heap = np.empty((1024, 2))
    # cells whose key does not exceed the key just popped are the next to expand anyway: they go on a
    # stack instead of through the heap (on a grid f rarely changes from a cell to its neighbour)
    stack = np.empty(1024, dtype=np.int64)
    top = 0
    g[s] = 0.0
    h0 = _heuristic(abs(s // width - gr), abs(s % width - gc), diagonal)
    size = heap_push(heap, 0, h0 * (1.0 + TIE), s)
    found = False
    while size > 0 or top > 0:
        if top > 0:
            top -= 1
            u = stack[top]
        else:
            _, u, size = heap_pop(heap, size)
        if u == t:
            found = True
            break
        if closed[u]:
            continue  # a stale entry (the cell was reached more cheaply since)
        closed[u] = 1
        gu = g[u]
        if gu > limit:
            break
        ur, uc = u // width, u % width
        hu = _heuristic(abs(ur - gr), abs(uc - gc), diagonal)
        key_u = gu + hu + TIE * hu
        for k in range(n_steps):
            v = u + offset[k]
            if pad[v] == 0 or closed[v]:
                continue
            if k >= 4 and (pad[u + side_r[k]] == 0 or pad[u + side_c[k]] == 0):
                continue
            candidate = gu + cost[k]
            if candidate < g[v]:
                g[v] = candidate
                parent[v] = u
                h = _heuristic(abs(ur + steps[k, 0] - gr), abs(uc + steps[k, 1] - gc), diagonal)
                key = candidate + h + TIE * h
                if key <= key_u:
                    if top == len(stack):
                        stack = np.concatenate((stack, np.empty_like(stack)))
                    stack[top] = v
                    top += 1
                else:
                    heap = heap_reserve(heap, size)
                    size = heap_push(heap, size, key, v)
    if not found:
        return np.inf, np.zeros(0, dtype=np.int64)
    count, u = 0, t
    while u >= 0:
        count += 1
        u = parent[u]
    path = np.empty(count, dtype=np.int64)
    u = t
    for i in range(count - 1, -1, -1):
        path[i] = (u // width - 1) * cols + u % width - 1
        u = parent[u]
    return g[t], path


@numba.njit(cache=True, nogil=True)
def search_kernel_4(free: np.ndarray, start: int, goal: int, limit: float):
    """A* for 4-connected unit steps with the Manhattan heuristic, on a bucket queue.

    Every key f = g + h is an integer and, the heuristic being consistent, the keys popped never
    decrease, so a queue of buckets indexed by f (each a LIFO list of entries; the newest, deepest cell
    first) replaces the binary heap: push and pop are O(1). Stale entries (a cell reached again more
    cheaply) are skipped once the cell is closed. One byte per cell says blocked (0), open (1) or
    closed (2); costs are 32-bit; no parent array is kept: the path is traced back from the goal
    through neighbours one step cheaper, the lowest flat index first (any such chain is a shortest
    path). Together they halve the memory the search touches.

    Returns:
        ``(cost in cells or inf, path (K,) int64 flat ids from start to goal; empty when none)``.
    """
    rows, cols = free.shape
    width = cols + 2  # padded with a blocked border
    n = (rows + 2) * width
    pad = np.zeros(n, dtype=np.uint8)
    for r in range(rows):
        base = (r + 1) * width + 1
        pad[base : base + cols] = free[r]
    s = (start // cols + 1) * width + start % cols + 1
    t = (goal // cols + 1) * width + goal % cols + 1
    gr, gc = t // width, t % width
    g = np.full(n, np.iinfo(np.int32).max, dtype=np.int32)
    max_f = rows * cols + rows + cols + 2  # no simple path is longer than the cell count
    h0 = abs(s // width - gr) + abs(s % width - gc)
    head = np.full(max_f + 1, -1, dtype=np.int32)  # bucket f → its newest entry
    entry_cell = np.empty(4096, dtype=np.int32)
    entry_next = np.empty(4096, dtype=np.int32)
    g[s] = 0
    f = h0
    entry_cell[0], entry_next[0], head[f] = s, -1, 0
    entries = 1
    found = False
    while f <= max_f:
        e = head[f]
        if e < 0:
            f += 1
            continue
        head[f] = entry_next[e]
        u = entry_cell[e]
        if pad[u] == 2:
            continue
        if u == t:
            found = True
            break
        pad[u] = 2
        gv = g[u] + 1
        if gv - 1 > limit:
            break
        ur, uc = u // width, u % width
        for k in range(4):
            if k == 0:
                v, h = u - width, abs(ur - 1 - gr) + abs(uc - gc)
            elif k == 1:
                v, h = u + width, abs(ur + 1 - gr) + abs(uc - gc)
            elif k == 2:
                v, h = u - 1, abs(ur - gr) + abs(uc - 1 - gc)
            else:
                v, h = u + 1, abs(ur - gr) + abs(uc + 1 - gc)
            if pad[v] != 1 or gv >= g[v]:
                continue
            g[v] = gv
            key = gv + h
            if entries == len(entry_cell):
                entry_cell = np.concatenate((entry_cell, np.empty_like(entry_cell)))
                entry_next = np.concatenate((entry_next, np.empty_like(entry_next)))
            entry_cell[entries], entry_next[entries] = v, head[key]
            head[key] = entries
            entries += 1
    if not found:
        return np.inf, np.zeros(0, dtype=np.int64)
    count = int(g[t]) + 1
    path = np.empty(count, dtype=np.int64)
    u = t
    for i in range(count - 1, -1, -1):
        path[i] = (u // width - 1) * cols + u % width - 1
        if i == 0:
            break
        for v in (u - width, u - 1, u + 1, u + width):  # the lowest flat index first
            if pad[v] != 0 and g[v] == g[u] - 1:
                u = v
                break
    return float(g[t]), path
