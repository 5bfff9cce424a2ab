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


@numba.njit(cache=True, nogil=True)
def preferred_velocities(pos, cur, nxt, has_next, goal, speed, moving, radius, dt):  # pragma: no cover
    """(N, 2) Detour's smooth steer toward the corners, slowing within 2r of the goal (0 for non-walkers).

    Toward ``cur`` pulled early by ``nxt`` (``dir0 − dir1 · |dir0| / 2``, Detour's
    ``calcSmoothSteerDirection``) when the corner is not the goal; the speed falls linearly within
    ``2 · radius`` of the goal and never overshoots it in one step ``dt``.
    """
    n = len(pos)
    pref = np.zeros((n, 2))
    for i in range(n):
        if not moving[i]:
            continue
        d0x, d0y = cur[i, 0] - pos[i, 0], cur[i, 1] - pos[i, 1]
        len0 = np.hypot(d0x, d0y)
        d1x, d1y = nxt[i, 0] - pos[i, 0], nxt[i, 1] - pos[i, 1]
        len1 = max(np.hypot(d1x, d1y), 1e-3)
        d1x, d1y = d1x / len1, d1y / len1
        sx, sy = d0x, d0y
        if has_next[i]:
            sx, sy = d0x - d1x * (0.5 * len0), d0y - d1y * (0.5 * len0)
        d_goal = np.hypot(goal[i, 0] - pos[i, 0], goal[i, 1] - pos[i, 1])
        desired = speed[i] * min(1.0, d_goal / (2.0 * radius))
        if not has_next[i]:
            desired = min(desired, len0 / dt)
        norm = max(np.hypot(sx, sy), 1e-9)
        pref[i, 0], pref[i, 1] = sx / norm * desired, sy / norm * desired
    return pref
