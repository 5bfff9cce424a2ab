"""Compiled pair loops of the crowd simulation's frame step (numba).

At indoor crowd sizes (tens of pedestrians) the numpy forms of these all-pairs computations cost more in
array set-up than in arithmetic, and they run several times per frame; their reference twins live in
:mod:`song.pipeline.crowd._simulate_reference`.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def near_walkers(pos: np.ndarray, moving: np.ndarray, reach: float) -> np.ndarray:  # pragma: no cover
    """(N,) bool: pedestrians closer than ``reach`` (m) to a moving pedestrian other than themselves."""
    n = len(pos)
    out = np.zeros(n, dtype=np.bool_)
    reach_sq = reach * reach
    for j in range(n):
        if not moving[j]:
            continue
        for i in range(n):
            if i != j and not out[i]:
                dx, dy = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1]
                if dx * dx + dy * dy < reach_sq:
                    out[i] = True
    return out


@numba.njit(cache=True, nogil=True)
def overlap_push(
    target: np.ndarray, moving: np.ndarray, min_dist: float
) -> tuple[np.ndarray, bool]:  # pragma: no cover
    """Pushes (N, 2) m separating overlapping pairs to ``min_dist``, and whether any pair overlaps.

    A walker moves half the overlap with another walker and all of it with someone standing; a
    standing pedestrian is not pushed.
    """
    n = len(target)
    push = np.zeros((n, 2))
    found = False
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            dx, dy = target[i, 0] - target[j, 0], target[i, 1] - target[j, 1]
            dist = np.hypot(dx, dy)
            overlap = min_dist - dist
            if overlap <= 0.0:
                continue
            found = True
            if moving[i]:
                share = 0.5 if moving[j] else 1.0
                scale = share * overlap / max(dist, 1e-9)
                push[i, 0] += dx * scale
                push[i, 1] += dy * scale
    return push, found
