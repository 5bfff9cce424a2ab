"""Plain ORCA, one agent at a time, statement by statement after RVO2's ``Agent.cpp`` and ``KdTree.cpp``.

The reference twin of the compiled kernel behind :func:`song.pipeline.crowd.orca.orca_step` (same
contract, same float64 arithmetic): agent neighbours by RVO2's insertion into a sorted, capped list;
obstacle neighbours by RVO2's recursive walk of the obstacle BSP tree; the obstacle and agent ORCA
lines of ``computeNewVelocity``; the incremental ``linearProgram1/2`` and ``linearProgram3``. Slow and
obvious on purpose: tests compare the kernel with it.
"""

from __future__ import annotations

import math

import numpy as np

from song.pipeline.crowd.orca import EPS, ObstacleSet, OrcaParams

Vec = tuple[float, float]
Line = tuple[Vec, Vec]  # (point, direction): velocities on the left of the direction are allowed


def _det(a: Vec, b: Vec) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1]


def _sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1])


def _add(a: Vec, b: Vec) -> Vec:
    return (a[0] + b[0], a[1] + b[1])


def _mul(k: float, a: Vec) -> Vec:
    return (k * a[0], k * a[1])


def _normalize(a: Vec) -> Vec:
    n = math.sqrt(_dot(a, a))
    return (a[0] / n, a[1] / n)


def _left_of(a: Vec, b: Vec, c: Vec) -> float:
    return _det(_sub(a, c), _sub(b, a))


def _agent_neighbours(i: int, pos: list[Vec], params: OrcaParams) -> list[int]:
    """``insertAgentNeighbor`` over all agents in index order: a sorted list capped at max_neighbors."""
    found: list[tuple[float, int]] = []
    range_sq = params.neighbor_dist**2
    for j in range(len(pos)):
        if j == i:
            continue
        d = _sub(pos[i], pos[j])
        dist_sq = _dot(d, d)
        if dist_sq < range_sq:
            if len(found) < params.max_neighbors:
                found.append((dist_sq, j))
            k = len(found) - 1
            while k != 0 and dist_sq < found[k - 1][0]:
                found[k] = found[k - 1]
                k -= 1
            found[k] = (dist_sq, j)
            if len(found) == params.max_neighbors:
                range_sq = found[-1][0]
    return [j for _, j in found]


def _obstacle_neighbours(p: Vec, range_sq: float, obs: ObstacleSet) -> list[int]:
    """``queryObstacleTreeRecursive`` + ``insertObstacleNeighbor``: edge start vertices, nearest first."""
    pts = [tuple(map(float, q)) for q in obs.points]
    found: list[tuple[float, int]] = []

    def insert(v: int) -> None:
        a, b = pts[v], pts[int(obs.next[v])]
        e = _sub(b, a)
        r = _dot(_sub(p, a), e) / _dot(e, e)
        if r < 0.0:
            dist_sq = _dot(_sub(p, a), _sub(p, a))
        elif r > 1.0:
            dist_sq = _dot(_sub(p, b), _sub(p, b))
        else:
            c = _sub(p, _add(a, _mul(r, e)))
            dist_sq = _dot(c, c)
        if dist_sq < range_sq:
            found.append((dist_sq, v))
            k = len(found) - 1
            while k != 0 and dist_sq < found[k - 1][0]:
                found[k] = found[k - 1]
                k -= 1
            found[k] = (dist_sq, v)

    def query(v: int) -> None:
        if v < 0:
            return
        a, b = pts[v], pts[int(obs.next[v])]
        side = _left_of(a, b, p)
        query(int(obs.node_left[v] if side >= 0.0 else obs.node_right[v]))
        e = _sub(b, a)
        if side * side / _dot(e, e) < range_sq:
            if side < 0.0:
                insert(v)
            query(int(obs.node_right[v] if side >= 0.0 else obs.node_left[v]))

    query(obs.root)
    return [v for _, v in found]


def _obstacle_lines(p: Vec, v: Vec, radius: float, max_speed: float, obs: ObstacleSet, params: OrcaParams):
    """The first loop of ``computeNewVelocity``: ORCA lines of the obstacle neighbours."""
    lines: list[Line] = []
    inv = 1.0 / params.time_horizon_obst
    reach = params.time_horizon_obst * max_speed + radius
    pts = [tuple(map(float, q)) for q in obs.points]
    dirs = [tuple(map(float, q)) for q in obs.directions]
    convex, nxt, prev = obs.convex, obs.next, obs.prev
    for o1 in _obstacle_neighbours(p, reach * reach, obs):
        o2 = int(nxt[o1])
        rp1, rp2 = _sub(pts[o1], p), _sub(pts[o2], p)
        covered = False
        for lp, ld in lines:
            if (
                _det(_sub(_mul(inv, rp1), lp), ld) - inv * radius >= -EPS
                and _det(_sub(_mul(inv, rp2), lp), ld) - inv * radius >= -EPS
            ):
                covered = True
                break
        if covered:
            continue
        dist_sq1, dist_sq2, r_sq = _dot(rp1, rp1), _dot(rp2, rp2), radius * radius
        ov = _sub(pts[o2], pts[o1])
        s = _dot(_mul(-1.0, rp1), ov) / _dot(ov, ov)
        dl = _sub(_mul(-1.0, rp1), _mul(s, ov))
        dist_sq_line = _dot(dl, dl)
        if s < 0.0 and dist_sq1 <= r_sq:
            if convex[o1]:
                lines.append(((0.0, 0.0), _normalize((-rp1[1], rp1[0]))))
            continue
        if s > 1.0 and dist_sq2 <= r_sq:
            if convex[o2] and _det(rp2, dirs[o2]) >= 0.0:
                lines.append(((0.0, 0.0), _normalize((-rp2[1], rp2[0]))))
            continue
        if 0.0 <= s <= 1.0 and dist_sq_line <= r_sq:
            lines.append(((0.0, 0.0), _mul(-1.0, dirs[o1])))
            continue
        if s < 0.0 and dist_sq_line <= r_sq:
            if not convex[o1]:
                continue
            o2 = o1
            left, right = _legs(rp1, dist_sq1, radius)
        elif s > 1.0 and dist_sq_line <= r_sq:
            if not convex[o2]:
                continue
            o1 = o2
            left, right = _legs(rp2, dist_sq2, radius)
        else:
            left = _legs(rp1, dist_sq1, radius)[0] if convex[o1] else _mul(-1.0, dirs[o1])
            right = _legs(rp2, dist_sq2, radius)[1] if convex[o2] else dirs[o1]
        left_neighbour = int(prev[o1])
        foreign_left = foreign_right = False
        if convex[o1] and _det(left, _mul(-1.0, dirs[left_neighbour])) >= 0.0:
            left, foreign_left = _mul(-1.0, dirs[left_neighbour]), True
        if convex[o2] and _det(right, dirs[o2]) <= 0.0:
            right, foreign_right = dirs[o2], True
        left_cut, right_cut = _mul(inv, _sub(pts[o1], p)), _mul(inv, _sub(pts[o2], p))
        cut_vec = _sub(right_cut, left_cut)
        t = 0.5 if o1 == o2 else _dot(_sub(v, left_cut), cut_vec) / _dot(cut_vec, cut_vec)
        t_left, t_right = _dot(_sub(v, left_cut), left), _dot(_sub(v, right_cut), right)
        if (t < 0.0 and t_left < 0.0) or (o1 == o2 and t_left < 0.0 and t_right < 0.0):
            unit = _normalize(_sub(v, left_cut))
            lines.append((_add(left_cut, _mul(radius * inv, unit)), (unit[1], -unit[0])))
            continue
        if t > 1.0 and t_right < 0.0:
            unit = _normalize(_sub(v, right_cut))
            lines.append((_add(right_cut, _mul(radius * inv, unit)), (unit[1], -unit[0])))
            continue
        inf = math.inf
        d_cut = inf if (t < 0.0 or t > 1.0 or o1 == o2) else _sq(_sub(v, _add(left_cut, _mul(t, cut_vec))))
        d_left = inf if t_left < 0.0 else _sq(_sub(v, _add(left_cut, _mul(t_left, left))))
        d_right = inf if t_right < 0.0 else _sq(_sub(v, _add(right_cut, _mul(t_right, right))))
        if d_cut <= d_left and d_cut <= d_right:
            d = _mul(-1.0, dirs[o1])
            lines.append((_add(left_cut, _mul(radius * inv, (-d[1], d[0]))), d))
            continue
        if d_left <= d_right:
            if not foreign_left:
                lines.append((_add(left_cut, _mul(radius * inv, (-left[1], left[0]))), left))
            continue
        if not foreign_right:
            d = _mul(-1.0, right)
            lines.append((_add(right_cut, _mul(radius * inv, (-d[1], d[0]))), d))
    return lines


def _sq(a: Vec) -> float:
    return _dot(a, a)


def _legs(rp: Vec, dist_sq: float, radius: float) -> tuple[Vec, Vec]:
    leg = math.sqrt(dist_sq - radius * radius)
    left = ((rp[0] * leg - rp[1] * radius) / dist_sq, (rp[0] * radius + rp[1] * leg) / dist_sq)
    right = ((rp[0] * leg + rp[1] * radius) / dist_sq, (-rp[0] * radius + rp[1] * leg) / dist_sq)
    return left, right


def _agent_line(
    p: Vec, v: Vec, r: float, q: Vec, w_other: Vec, r_other: float, params: OrcaParams, share: float = 0.5
) -> Line:
    """The second loop of ``computeNewVelocity``: the ORCA line for one neighbour."""
    rel_pos, rel_vel = _sub(q, p), _sub(v, w_other)
    dist_sq = _dot(rel_pos, rel_pos)
    comb = r + r_other
    comb_sq = comb * comb
    if dist_sq > comb_sq:
        inv = 1.0 / params.time_horizon
        w = _sub(rel_vel, _mul(inv, rel_pos))
        w_sq = _dot(w, w)
        dot = _dot(w, rel_pos)
        if dot < 0.0 and dot * dot > comb_sq * w_sq:
            w_len = math.sqrt(w_sq)
            unit = (w[0] / w_len, w[1] / w_len)
            direction = (unit[1], -unit[0])
            u = _mul(comb * inv - w_len, unit)
        else:
            left, right = _legs(rel_pos, dist_sq, comb)
            direction = left if _det(rel_pos, w) > 0.0 else _mul(-1.0, right)
            u = _sub(_mul(_dot(rel_vel, direction), direction), rel_vel)
    else:
        inv_dt = 1.0 / params.time_step
        w = _sub(rel_vel, _mul(inv_dt, rel_pos))
        w_len = math.sqrt(_dot(w, w))
        unit = (w[0] / w_len, w[1] / w_len)
        direction = (unit[1], -unit[0])
        u = _mul(comb * inv_dt - w_len, unit)
    return (_add(v, _mul(share, u)), direction)


def _lp1(lines: list[Line], no: int, radius: float, opt: Vec, direction_opt: bool) -> Vec | None:
    p, d = lines[no]
    dot = _dot(p, d)
    disc = dot * dot + radius * radius - _dot(p, p)
    if disc < 0.0:
        return None
    sq = math.sqrt(disc)
    t_left, t_right = -dot - sq, -dot + sq
    for i in range(no):
        pi, di = lines[i]
        denom = _det(d, di)
        numer = _det(di, _sub(p, pi))
        if abs(denom) <= EPS:
            if numer < 0.0:
                return None
            continue
        t = numer / denom
        if denom >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return None
    if direction_opt:
        return _add(p, _mul(t_right if _dot(opt, d) > 0.0 else t_left, d))
    t = _dot(d, _sub(opt, p))
    return _add(p, _mul(min(max(t, t_left), t_right), d))


def _lp2(lines: list[Line], radius: float, opt: Vec, direction_opt: bool) -> tuple[int, Vec]:
    if direction_opt:
        result = _mul(radius, opt)
    elif _dot(opt, opt) > radius * radius:
        n = math.sqrt(_dot(opt, opt))
        result = (opt[0] / n * radius, opt[1] / n * radius)
    else:
        result = opt
    for i, (p, d) in enumerate(lines):
        if _det(d, _sub(p, result)) > 0.0:
            new = _lp1(lines, i, radius, opt, direction_opt)
            if new is None:
                return i, result
            result = new
    return len(lines), result


def _lp3(lines: list[Line], n_obst: int, begin: int, radius: float, result: Vec) -> Vec:
    distance = 0.0
    for i in range(begin, len(lines)):
        pi, di = lines[i]
        if _det(di, _sub(pi, result)) > distance:
            proj = list(lines[:n_obst])
            for j in range(n_obst, i):
                pj, dj = lines[j]
                det = _det(di, dj)
                if abs(det) <= EPS:
                    if _dot(di, dj) > 0.0:
                        continue
                    point = _mul(0.5, _add(pi, pj))
                else:
                    point = _add(pi, _mul(_det(dj, _sub(pi, pj)) / det, di))
                proj.append((point, _normalize(_sub(dj, di))))
            fail, new = _lp2(proj, radius, (-di[1], di[0]), True)
            if fail == len(proj):
                result = new
            distance = _det(di, _sub(pi, result))
    return result


def _keep_pace(lines: list[Line], result: Vec, pref: Vec, top: float) -> Vec:
    """Twin of the kernel's ``_keep_pace``: the LP answer lengthened toward the preferred speed, within the lines."""
    want, have = min(math.hypot(*pref), top), math.hypot(*result)
    if have <= EPS or have >= want or _dot(result, pref) <= 0.0:
        return result
    caps = [_det(d, p) / _det(d, result) for p, d in lines if _det(d, result) < 0.0]
    return _mul(max(min([want / have, *caps]), 1.0), result)


def orca_step_reference(
    positions,
    velocities,
    pref_velocities,
    radii,
    max_speeds,
    obstacles: ObstacleSet | None,
    params: OrcaParams,
    wall_radii=None,
) -> np.ndarray:
    """Same contract as :func:`song.pipeline.crowd.orca.orca_step`, one agent at a time."""
    pos = [tuple(map(float, q)) for q in np.asarray(positions, dtype=np.float64)]
    vel = [tuple(map(float, q)) for q in np.asarray(velocities, dtype=np.float64)]
    pref = [tuple(map(float, q)) for q in np.asarray(pref_velocities, dtype=np.float64)]
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(pos),))
    speeds = np.broadcast_to(np.asarray(max_speeds, dtype=np.float64), (len(pos),))
    walls = radii if wall_radii is None else np.broadcast_to(np.asarray(wall_radii, dtype=np.float64), (len(pos),))
    out = np.zeros((len(pos), 2))
    for i in range(len(pos)):
        r, speed = float(radii[i]), float(speeds[i])
        lines: list[Line] = []
        if obstacles is not None and obstacles.n_vertices:
            lines = _obstacle_lines(pos[i], vel[i], float(walls[i]), speed, obstacles, params)
        n_obst = len(lines)
        for j in _agent_neighbours(i, pos, params):
            share = 1.0 if params.static_full_responsibility and speeds[j] == 0.0 else 0.5
            lines.append(_agent_line(pos[i], vel[i], r, pos[j], vel[j], float(radii[j]), params, share))
        fail, result = _lp2(lines, speed, pref[i], False)
        if fail < len(lines):
            result = _lp3(lines, n_obst, fail, speed, result)
        elif params.keep_pace:
            result = _keep_pace(lines, result, pref[i], speed)
        out[i] = result
    return out
