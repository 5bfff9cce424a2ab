"""Plain per-agent ORCA, line by line after RVO2's Agent.cpp: the reference twin of ``orca.py``."""

from __future__ import annotations

import math

import numpy as np

from song.pipeline.crowd.orca import EPS, OrcaParams


def _det(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _lines_for(i, positions, velocities, radii, params):
    others = [j for j in range(len(positions)) if j != i]
    dists = sorted((float(np.sum((positions[j] - positions[i]) ** 2)), j) for j in others)
    lines = []
    for dist_sq, j in dists[: params.max_neighbors]:
        if dist_sq >= params.neighbor_dist**2:
            continue
        rel_pos = positions[j] - positions[i]
        rel_vel = velocities[i] - velocities[j]
        r = radii[i] + radii[j]
        if dist_sq > r * r:
            w = rel_vel - rel_pos / params.time_horizon
            w_sq = float(w @ w)
            dot1 = float(w @ rel_pos)
            if dot1 < 0 and dot1 * dot1 > r * r * w_sq:
                w_len = math.sqrt(w_sq)
                unit = w / w_len
                direction = np.array([unit[1], -unit[0]])
                u = (r / params.time_horizon - w_len) * unit
            else:
                leg = math.sqrt(dist_sq - r * r)
                if _det(rel_pos, w) > 0:
                    direction = (
                        np.array([rel_pos[0] * leg - rel_pos[1] * r, rel_pos[0] * r + rel_pos[1] * leg]) / dist_sq
                    )
                else:
                    direction = (
                        -np.array([rel_pos[0] * leg + rel_pos[1] * r, -rel_pos[0] * r + rel_pos[1] * leg]) / dist_sq
                    )
                u = float(rel_vel @ direction) * direction - rel_vel
        else:
            w = rel_vel - rel_pos / params.time_step
            w_len = math.sqrt(float(w @ w))
            unit = w / w_len
            direction = np.array([unit[1], -unit[0]])
            u = (r / params.time_step - w_len) * unit
        lines.append((velocities[i] + 0.5 * u, direction))
    return lines


def _lp1(lines, no, radius, opt, direction_opt):
    p, d = lines[no]
    dot = float(p @ d)
    disc = dot * dot + radius * radius - float(p @ p)
    if disc < 0:
        return None
    sq = math.sqrt(disc)
    t_left, t_right = -dot - sq, -dot + sq
    for i in range(no):
        pi, di = lines[i]
        denom = _det(d, di)
        numer = _det(di, p - pi)
        if abs(denom) <= EPS:
            if numer < 0:
                return None
            continue
        t = numer / denom
        if denom >= 0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return None
    if direction_opt:
        return p + (t_right if float(opt @ d) > 0 else t_left) * d
    t = float(d @ (opt - p))
    return p + min(max(t, t_left), t_right) * d


def _lp2(lines, radius, opt, direction_opt):
    if direction_opt:
        result = opt * radius
    elif float(opt @ opt) > radius * radius:
        result = opt / math.sqrt(float(opt @ opt)) * radius
    else:
        result = opt.copy()
    for i, (p, d) in enumerate(lines):
        if _det(d, p - result) > 0:
            new = _lp1(lines, i, radius, opt, direction_opt)
            if new is None:
                return i, result
            result = new
    return len(lines), result


def _lp3(lines, begin, radius, result):
    distance = 0.0
    for i in range(begin, len(lines)):
        pi, di = lines[i]
        if _det(di, pi - result) > distance:
            proj = []
            for j in range(i):
                pj, dj = lines[j]
                det = _det(di, dj)
                if abs(det) <= EPS:
                    if float(di @ dj) > 0:
                        continue
                    point = 0.5 * (pi + pj)
                else:
                    point = pi + (_det(dj, pi - pj) / det) * di
                direction = dj - di
                proj.append((point, direction / math.sqrt(float(direction @ direction))))
            temp = result
            fail, result = _lp2(proj, radius, np.array([-di[1], di[0]]), True)
            if fail < len(proj):
                result = temp
            distance = _det(di, pi - result)
    return result


def orca_step_reference(positions, velocities, pref_velocities, radii, max_speeds, params: OrcaParams) -> np.ndarray:
    """Same contract as :func:`song.pipeline.crowd.orca.orca_step`, one agent at a time."""
    out = np.zeros((len(positions), 2))
    for i in range(len(positions)):
        lines = _lines_for(i, positions, velocities, radii, params)
        fail, result = _lp2(lines, max_speeds[i], np.asarray(pref_velocities[i], float), False)
        if fail < len(lines):
            result = _lp3(lines, fail, max_speeds[i], result)
        out[i] = result
    return out
