"""ORCA (optimal reciprocal collision avoidance) between agents, vectorised over agents (numpy).

Semantics follow RVO2's ``Agent::computeNewVelocity`` for agent–agent constraints: each neighbour
within ``neighbor_dist`` (the ``max_neighbors`` nearest) contributes a half-plane of permitted
velocities with reciprocal ½ responsibility, cut off at ``time_horizon`` (or, when already
overlapping, at one time step); the new velocity is the one closest to the preferred velocity inside
all half-planes and the max-speed disc, found by the 2-D incremental LP (``linearProgram1/2``).
When the 2-D LP is infeasible (a dense crowd), the 3-D LP (``linearProgram3``) picks the velocity
that minimises the largest violation, as RVO2 does. Walls are handled by the crowd simulation
(positions constrained to the walkable area), not here. ``_reference.py`` holds a per-agent twin.

Every LP step runs for all agents at once with masks, which is what makes it fast in numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EPS = 1e-5  # RVO_EPSILON


@dataclass(frozen=True)
class OrcaParams:
    """Time step (s), neighbour search (m, count) and time horizon (s)."""

    time_step: float
    neighbor_dist: float
    max_neighbors: int
    time_horizon: float


def _det(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def neighbours(positions: np.ndarray, params: OrcaParams) -> tuple[np.ndarray, np.ndarray]:
    """(N, K) neighbour indices sorted by distance and a validity mask (within distance, not self)."""
    n = len(positions)
    k = min(params.max_neighbors, max(n - 1, 0))
    if k == 0:
        return np.zeros((n, 0), dtype=np.int64), np.zeros((n, 0), dtype=bool)
    d2 = ((positions[:, None, :] - positions[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    order = np.argsort(d2, axis=1, kind="stable")[:, :k]
    valid = np.take_along_axis(d2, order, axis=1) < params.neighbor_dist**2
    return order, valid


def agent_lines(
    positions: np.ndarray, velocities: np.ndarray, radii: np.ndarray, params: OrcaParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ORCA half-planes: ``(points (N, K, 2), directions (N, K, 2), valid (N, K))``.

    A velocity v is permitted by line (p, d) when det(d, p − v) ≤ 0 (v on the left of d).
    """
    idx, valid = neighbours(positions, params)
    rel_pos = positions[idx] - positions[:, None, :]
    rel_vel = velocities[:, None, :] - velocities[idx]
    dist_sq = (rel_pos**2).sum(-1)
    r = radii[:, None] + radii[idx]
    r_sq = r**2
    inv_h = 1.0 / params.time_horizon
    apart = dist_sq > r_sq

    # not colliding: project on the cut-off circle or on a leg of the truncated cone
    w = rel_vel - inv_h * rel_pos
    w_sq = (w**2).sum(-1)
    dot1 = (w * rel_pos).sum(-1)
    on_circle = apart & (dot1 < 0.0) & (dot1**2 > r_sq * w_sq)
    w_len = np.sqrt(np.maximum(w_sq, 1e-300))
    unit_w = w / w_len[..., None]
    dir_circle = np.stack([unit_w[..., 1], -unit_w[..., 0]], -1)
    u_circle = (r * inv_h - w_len)[..., None] * unit_w
    leg = np.sqrt(np.maximum(dist_sq - r_sq, 0.0))
    px, py = rel_pos[..., 0], rel_pos[..., 1]
    safe_d = np.where(dist_sq > 0, dist_sq, 1.0)
    left = np.stack([px * leg - py * r, px * r + py * leg], -1) / safe_d[..., None]
    right = -np.stack([px * leg + py * r, -px * r + py * leg], -1) / safe_d[..., None]
    is_left = _det(rel_pos, w) > 0.0
    dir_leg = np.where(is_left[..., None], left, right)
    u_leg = (rel_vel * dir_leg).sum(-1)[..., None] * dir_leg - rel_vel

    # colliding: cut off at one time step
    inv_dt = 1.0 / params.time_step
    wc = rel_vel - inv_dt * rel_pos
    wc_len = np.sqrt(np.maximum((wc**2).sum(-1), 1e-300))
    unit_wc = wc / wc_len[..., None]
    dir_coll = np.stack([unit_wc[..., 1], -unit_wc[..., 0]], -1)
    u_coll = (r * inv_dt - wc_len)[..., None] * unit_wc

    direction = np.where(apart[..., None], np.where(on_circle[..., None], dir_circle, dir_leg), dir_coll)
    u = np.where(apart[..., None], np.where(on_circle[..., None], u_circle, u_leg), u_coll)
    points = velocities[:, None, :] + 0.5 * u
    return points, direction, valid


def _lp1(points, dirs, valid, line, radius, opt, rows, direction_opt=False):
    """linearProgram1 for the agents ``rows`` on their line ``line``; returns (ok, result).

    With ``direction_opt`` (used by linearProgram3), ``opt`` is a unit direction to go furthest along.
    """
    p = points[rows, line]
    d = dirs[rows, line]
    dot = (p * d).sum(-1)
    disc = dot**2 + radius[rows] ** 2 - (p**2).sum(-1)
    ok = disc >= 0.0
    sq = np.sqrt(np.maximum(disc, 0.0))
    t_left, t_right = -dot - sq, -dot + sq
    for j in range(line):
        use = valid[rows, j]
        denom = _det(d, dirs[rows, j])
        numer = _det(dirs[rows, j], p - points[rows, j])
        parallel = use & (np.abs(denom) <= EPS)
        ok &= ~(parallel & (numer < 0.0))
        t = numer / np.where(np.abs(denom) <= EPS, 1.0, denom)
        cut = use & ~parallel
        t_right = np.where(cut & (denom >= 0.0), np.minimum(t_right, t), t_right)
        t_left = np.where(cut & (denom < 0.0), np.maximum(t_left, t), t_left)
        ok &= t_left <= t_right
    if direction_opt:
        t = np.where((opt[rows] * d).sum(-1) > 0.0, t_right, t_left)
    else:
        t = np.clip((d * (opt[rows] - p)).sum(-1), t_left, t_right)
    return ok, p + t[:, None] * d


def _lp2(points, dirs, valid, radius, opt, direction_opt=False):
    """linearProgram2 for all agents; returns (result (N, 2), first failing line (N,), −1 = none)."""
    n, k = valid.shape
    speed = np.linalg.norm(opt, axis=1)
    if direction_opt:
        result = opt * radius[:, None]
    else:
        result = np.where((speed > radius)[:, None], opt / np.maximum(speed, 1e-300)[:, None] * radius[:, None], opt)
    fail = np.full(n, -1)
    for i in range(k):
        viol = valid[:, i] & (fail < 0) & (_det(dirs[:, i], points[:, i] - result) > 0.0)
        rows = np.flatnonzero(viol)
        if len(rows) == 0:
            continue
        ok, new = _lp1(points, dirs, valid, i, radius, opt, rows, direction_opt)
        result[rows[ok]] = new[ok]
        fail[rows[~ok]] = i
    return result, fail


def _lp3_single(points, dirs, valid, begin, radius, result):
    """linearProgram3 for one agent (rare: only agents whose 2-D LP failed)."""
    distance = 0.0
    order = [j for j in range(len(valid)) if valid[j]]
    for pos, i in enumerate(order):
        if i < begin:
            continue
        p_i, d_i = points[i], dirs[i]
        if _det(d_i, p_i - result) <= distance:
            continue
        proj_p, proj_d = [], []
        for j in order[:pos]:
            p_j, d_j = points[j], dirs[j]
            det = _det(d_i, d_j)
            if abs(det) <= EPS:
                if float(d_i @ d_j) > 0.0:
                    continue
                point = 0.5 * (p_i + p_j)
            else:
                point = p_i + (_det(d_j, p_i - p_j) / det) * d_i
            direction = d_j - d_i
            direction = direction / max(np.linalg.norm(direction), 1e-300)
            proj_p.append(point)
            proj_d.append(direction)
        temp = result
        opt = np.array([-d_i[1], d_i[0]])
        if proj_p:
            pp, dd = np.array(proj_p)[None], np.array(proj_d)[None]
            vv = np.ones((1, len(proj_p)), dtype=bool)
            res, fail = _lp2(pp, dd, vv, np.array([radius]), opt[None], direction_opt=True)
            result = temp if fail[0] >= 0 else res[0]
        else:
            result = opt * radius
        distance = _det(d_i, p_i - result)
    return result


def orca_step(
    positions: np.ndarray,
    velocities: np.ndarray,
    pref_velocities: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    params: OrcaParams,
) -> np.ndarray:
    """New velocities (N, 2) for all agents: ORCA half-planes + 2-D LP (3-D LP where infeasible).

    Args:
        positions, velocities, pref_velocities: (N, 2) float64, m and m/s.
        radii, max_speeds: (N,) float64, m and m/s.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if len(positions) == 0:
        return np.zeros((0, 2))
    points, dirs, valid = agent_lines(positions, np.asarray(velocities, float), np.asarray(radii, float), params)
    result, fail = _lp2(points, dirs, valid, np.asarray(max_speeds, float), np.asarray(pref_velocities, float))
    for a in np.flatnonzero(fail >= 0):
        result[a] = _lp3_single(points[a], dirs[a], valid[a], int(fail[a]), float(max_speeds[a]), result[a])
    return result
