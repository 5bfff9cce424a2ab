"""ORCA compiled with numba: RVO2's per-agent ``computeNeighbors`` + ``computeNewVelocity``, in float64.

The per-agent algorithm of ``_orca_reference.py`` (RVO2's ``Agent.cpp``/``KdTree.cpp`` statement by
statement) compiled to machine code -- numpy's per-call overhead dominates at the crowd sizes of indoor
scenes, so the algorithm is written as scalar loops: agent neighbours by sorted insertion capped at
``max_neighbors`` (from 64 agents on, searched ring by ring in a uniform grid, where RVO2 walks a k-d
tree; ties between equally distant agents go to the lower index either way), obstacle neighbours by the BSP-tree walk (made iterative with an explicit stack,
same visiting order), obstacle lines with legs, cut-off and foreign legs, agent lines,
``linearProgram1/2/3``. :mod:`song.pipeline.crowd.orca` is the Python entry point; tests compare it
with the reference twin and with RVO2 itself (pyrvo).
"""

from __future__ import annotations

import math

import numba
import numpy as np

EPS = 1e-5  # RVO_EPSILON: parallel-line threshold in the LPs, side tests in the obstacle tree


def _jit(fn):
    return numba.njit(cache=True, nogil=True)(fn)


@_jit
def _det(ax, ay, bx, by):
    return ax * by - ay * bx


@_jit
def _legs(rx, ry, dist_sq, radius):
    leg = math.sqrt(dist_sq - radius * radius)
    lx, ly = (rx * leg - ry * radius) / dist_sq, (rx * radius + ry * leg) / dist_sq
    qx, qy = (rx * leg + ry * radius) / dist_sq, (-rx * radius + ry * leg) / dist_sq
    return lx, ly, qx, qy


@_jit
def _insert_sorted(keys, values, n, capacity, key, value):
    """RVO2's insertion into a list sorted by key, capped at ``capacity`` (the last entry drops); returns n."""
    if n < capacity:
        n += 1
    k = n - 1
    while k != 0 and key < keys[k - 1]:
        keys[k], values[k] = keys[k - 1], values[k - 1]
        k -= 1
    keys[k], values[k] = key, value
    return n


@_jit
def _insert_neighbour(keys, values, n, capacity, key, value):
    """Insert (key, value) into the list sorted by (key, value), capped at ``capacity``; returns n.

    Ordering ties by index makes the list independent of the order candidates are visited in (grid
    cells or index order: the same as RVO2's insertion for index order).
    """
    if n == capacity:
        last = n - 1
        if key > keys[last] or (key == keys[last] and value > values[last]):
            return n
    else:
        n += 1
    k = n - 1
    while k != 0 and (key < keys[k - 1] or (key == keys[k - 1] and value < values[k - 1])):
        keys[k], values[k] = keys[k - 1], values[k - 1]
        k -= 1
    keys[k], values[k] = key, value
    return n


GRID_MIN_AGENTS = 64  # below this many agents the all-pairs scan beats building a grid
GRID_CELLS_PER_RANGE = 4  # cells per neighbour distance: a dense crowd's nearest few lie in the closest cells


@_jit
def agent_grid(pos, neighbor_dist):
    """Agents bucketed in square cells (a counting sort, index order kept within a cell).

    Cells are a quarter of ``neighbor_dist`` wide (coarser when the crowd is sparse over a large area,
    so that there are at most 16 cells per agent). Returns (start (C + 1,), items (N,), x0, y0, cell,
    nx, ny); ``nx == 0`` when there are too few agents for a grid to pay. RVO2 uses a k-d tree; the
    grid searched ring by ring gives the same neighbours.
    """
    n = pos.shape[0]
    if n < GRID_MIN_AGENTS:
        return np.zeros(1, np.int64), np.zeros(0, np.int64), 0.0, 0.0, 1.0, 0, 0
    x0, y0, x1, y1 = pos[0, 0], pos[0, 1], pos[0, 0], pos[0, 1]
    for i in range(n):
        x0, x1 = min(x0, pos[i, 0]), max(x1, pos[i, 0])
        y0, y1 = min(y0, pos[i, 1]), max(y1, pos[i, 1])
    cell = max(neighbor_dist / GRID_CELLS_PER_RANGE, 1e-6)
    while ((x1 - x0) / cell + 1) * ((y1 - y0) / cell + 1) > 16 * n + 4096:
        cell *= 2.0
    nx, ny = int((x1 - x0) / cell) + 1, int((y1 - y0) / cell) + 1
    cells = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        c = int((pos[i, 1] - y0) / cell) * nx + int((pos[i, 0] - x0) / cell)
        cells[i] = c
        start[c + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for i in range(n):
        items[fill[cells[i]]] = i
        fill[cells[i]] += 1
    return start, items, x0, y0, cell, nx, ny


@_jit
def _agent_neighbours(i, pos, neighbor_dist, max_neighbors, out_idx, out_d, grid):
    """Agent i's nearest ``max_neighbors`` agents within ``neighbor_dist``, nearest first (ties: lower index)."""
    range_sq = neighbor_dist * neighbor_dist
    n = 0
    start, items, x0, y0, cell, nx, ny = grid
    if nx == 0:
        for j in range(pos.shape[0]):
            dx, dy = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1]
            dist_sq = dx * dx + dy * dy
            if j != i and dist_sq < range_sq:
                n = _insert_neighbour(out_d, out_idx, n, max_neighbors, dist_sq, j)
        return n
    # rings of cells around i's own; a ring r lies at least (r - 1) cells away: stop once that is beyond
    # the neighbour distance or, with the list full, beyond its farthest entry
    cx, cy = int((pos[i, 0] - x0) / cell), int((pos[i, 1] - y0) / cell)
    rings = int(math.ceil(neighbor_dist / cell)) + 1
    for r in range(rings + 1):
        gap = (r - 1) * cell
        if r >= 2 and gap * gap >= (out_d[n - 1] if n == max_neighbors else range_sq):
            break
        for gy in range(cy - r, cy + r + 1):
            if gy < 0 or gy >= ny:
                continue
            step = 1 if gy == cy - r or gy == cy + r else 2 * r
            for gx in range(cx - r, cx + r + 1, max(step, 1)):
                if gx < 0 or gx >= nx:
                    continue
                c = gy * nx + gx  # scanned inline: a call per cell costs more than the scan (array arguments)
                for k in range(start[c], start[c + 1]):
                    j = items[k]
                    dx, dy = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1]
                    dist_sq = dx * dx + dy * dy
                    if j != i and dist_sq < range_sq:
                        n = _insert_neighbour(out_d, out_idx, n, max_neighbors, dist_sq, j)
    return n


@_jit
def _insert_obstacle(px, py, v, points, nxt, range_sq, found_v, found_d, n):
    ax, ay = points[v, 0], points[v, 1]
    bx, by = points[nxt[v], 0], points[nxt[v], 1]
    ex, ey = bx - ax, by - ay
    r = ((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey)
    if r < 0.0:
        dist_sq = (px - ax) ** 2 + (py - ay) ** 2
    elif r > 1.0:
        dist_sq = (px - bx) ** 2 + (py - by) ** 2
    else:
        cx, cy = px - (ax + r * ex), py - (ay + r * ey)
        dist_sq = cx * cx + cy * cy
    if dist_sq < range_sq:
        n = _insert_sorted(found_d, found_v, n, len(found_d), dist_sq, v)
    return n


@_jit
def _obstacle_neighbours(px, py, range_sq, points, nxt, left, right, root, found_v, found_d, stack):
    """RVO2's recursive tree query, iteratively: (node, phase) pairs on ``stack`` (V + 1, 2)."""
    n, top = 0, 0
    stack[0, 0], stack[0, 1] = root, 0
    top = 1
    while top > 0:
        top -= 1
        v, phase = stack[top, 0], stack[top, 1]
        if v < 0:
            continue
        ax, ay = points[v, 0], points[v, 1]
        bx, by = points[nxt[v], 0], points[nxt[v], 1]
        side = _det(ax - px, ay - py, bx - ax, by - ay)
        if phase == 0:
            stack[top, 0], stack[top, 1] = v, 1  # come back after the near side
            top += 1
            stack[top, 0], stack[top, 1] = (left[v] if side >= 0.0 else right[v]), 0
            top += 1
            continue
        ex, ey = bx - ax, by - ay
        if side * side / (ex * ex + ey * ey) < range_sq:
            if side < 0.0:
                n = _insert_obstacle(px, py, v, points, nxt, range_sq, found_v, found_d, n)
            stack[top, 0], stack[top, 1] = (right[v] if side >= 0.0 else left[v]), 0
            top += 1
    return n


@_jit
def _add_line(lines, n, px, py, dx, dy):
    lines[n, 0], lines[n, 1], lines[n, 2], lines[n, 3] = px, py, dx, dy
    return n + 1


@_jit
def _obstacle_lines(p, v, radius, max_speed, points, nxt, prv, dirs, convex, left_t, right_t, root, th_obst,
                    lines, found_v, found_d, stack):  # fmt: skip
    px, py, vx, vy = p[0], p[1], v[0], v[1]
    inv = 1.0 / th_obst
    reach = th_obst * max_speed + radius
    count = _obstacle_neighbours(px, py, reach * reach, points, nxt, left_t, right_t, root, found_v, found_d, stack)
    n = 0
    r_sq = radius * radius
    for idx in range(count):
        o1 = found_v[idx]
        o2 = nxt[o1]
        r1x, r1y = points[o1, 0] - px, points[o1, 1] - py
        r2x, r2y = points[o2, 0] - px, points[o2, 1] - py
        covered = False
        for k in range(n):
            lpx, lpy, ldx, ldy = lines[k, 0], lines[k, 1], lines[k, 2], lines[k, 3]
            if (
                _det(inv * r1x - lpx, inv * r1y - lpy, ldx, ldy) - inv * radius >= -EPS
                and _det(inv * r2x - lpx, inv * r2y - lpy, ldx, ldy) - inv * radius >= -EPS
            ):
                covered = True
                break
        if covered:
            continue
        d1, d2 = r1x * r1x + r1y * r1y, r2x * r2x + r2y * r2y
        ovx, ovy = points[o2, 0] - points[o1, 0], points[o2, 1] - points[o1, 1]
        s = (-r1x * ovx - r1y * ovy) / (ovx * ovx + ovy * ovy)
        dlx, dly = -r1x - s * ovx, -r1y - s * ovy
        d_line = dlx * dlx + dly * dly
        if s < 0.0 and d1 <= r_sq:
            if convex[o1]:
                norm = math.sqrt(r1x * r1x + r1y * r1y)
                n = _add_line(lines, n, 0.0, 0.0, -r1y / norm, r1x / norm)
            continue
        if s > 1.0 and d2 <= r_sq:
            if convex[o2] and _det(r2x, r2y, dirs[o2, 0], dirs[o2, 1]) >= 0.0:
                norm = math.sqrt(r2x * r2x + r2y * r2y)
                n = _add_line(lines, n, 0.0, 0.0, -r2y / norm, r2x / norm)
            continue
        if 0.0 <= s <= 1.0 and d_line <= r_sq:
            n = _add_line(lines, n, 0.0, 0.0, -dirs[o1, 0], -dirs[o1, 1])
            continue
        if s < 0.0 and d_line <= r_sq:
            if not convex[o1]:
                continue
            o2 = o1
            lx, ly, rx, ry = _legs(r1x, r1y, d1, radius)
        elif s > 1.0 and d_line <= r_sq:
            if not convex[o2]:
                continue
            o1 = o2
            lx, ly, rx, ry = _legs(r2x, r2y, d2, radius)
        else:
            if convex[o1]:
                lx, ly, _, _ = _legs(r1x, r1y, d1, radius)
            else:
                lx, ly = -dirs[o1, 0], -dirs[o1, 1]
            if convex[o2]:
                _, _, rx, ry = _legs(r2x, r2y, d2, radius)
            else:
                rx, ry = dirs[o1, 0], dirs[o1, 1]
        ln = prv[o1]
        foreign_left = foreign_right = False
        if convex[o1] and _det(lx, ly, -dirs[ln, 0], -dirs[ln, 1]) >= 0.0:
            lx, ly, foreign_left = -dirs[ln, 0], -dirs[ln, 1], True
        if convex[o2] and _det(rx, ry, dirs[o2, 0], dirs[o2, 1]) <= 0.0:
            rx, ry, foreign_right = dirs[o2, 0], dirs[o2, 1], True
        lcx, lcy = inv * (points[o1, 0] - px), inv * (points[o1, 1] - py)
        rcx, rcy = inv * (points[o2, 0] - px), inv * (points[o2, 1] - py)
        cvx, cvy = rcx - lcx, rcy - lcy
        t = 0.5 if o1 == o2 else ((vx - lcx) * cvx + (vy - lcy) * cvy) / (cvx * cvx + cvy * cvy)
        t_left = (vx - lcx) * lx + (vy - lcy) * ly
        t_right = (vx - rcx) * rx + (vy - rcy) * ry
        if (t < 0.0 and t_left < 0.0) or (o1 == o2 and t_left < 0.0 and t_right < 0.0):
            ux, uy = vx - lcx, vy - lcy
            norm = math.sqrt(ux * ux + uy * uy)
            ux, uy = ux / norm, uy / norm
            n = _add_line(lines, n, lcx + radius * inv * ux, lcy + radius * inv * uy, uy, -ux)
            continue
        if t > 1.0 and t_right < 0.0:
            ux, uy = vx - rcx, vy - rcy
            norm = math.sqrt(ux * ux + uy * uy)
            ux, uy = ux / norm, uy / norm
            n = _add_line(lines, n, rcx + radius * inv * ux, rcy + radius * inv * uy, uy, -ux)
            continue
        d_cut = math.inf
        if not (t < 0.0 or t > 1.0 or o1 == o2):
            d_cut = (vx - (lcx + t * cvx)) ** 2 + (vy - (lcy + t * cvy)) ** 2
        d_left = math.inf if t_left < 0.0 else (vx - (lcx + t_left * lx)) ** 2 + (vy - (lcy + t_left * ly)) ** 2
        d_right = math.inf if t_right < 0.0 else (vx - (rcx + t_right * rx)) ** 2 + (vy - (rcy + t_right * ry)) ** 2
        if d_cut <= d_left and d_cut <= d_right:
            dx, dy = -dirs[o1, 0], -dirs[o1, 1]
            n = _add_line(lines, n, lcx + radius * inv * -dy, lcy + radius * inv * dx, dx, dy)
            continue
        if d_left <= d_right:
            if not foreign_left:
                n = _add_line(lines, n, lcx + radius * inv * -ly, lcy + radius * inv * lx, lx, ly)
            continue
        if not foreign_right:
            dx, dy = -rx, -ry
            n = _add_line(lines, n, rcx + radius * inv * -dy, rcy + radius * inv * dx, dx, dy)
    return n


@_jit
def _agent_line(lines, n, px, py, vx, vy, r, qx, qy, wx, wy, r_other, time_horizon, time_step, share):
    rpx, rpy = qx - px, qy - py
    rvx, rvy = vx - wx, vy - wy
    dist_sq = rpx * rpx + rpy * rpy
    comb = r + r_other
    comb_sq = comb * comb
    if dist_sq > comb_sq:
        inv = 1.0 / time_horizon
        w_x, w_y = rvx - inv * rpx, rvy - inv * rpy
        w_sq = w_x * w_x + w_y * w_y
        dot = w_x * rpx + w_y * rpy
        if dot < 0.0 and dot * dot > comb_sq * w_sq:
            w_len = math.sqrt(w_sq)
            ux, uy = w_x / w_len, w_y / w_len
            dx, dy = uy, -ux
            k = comb * inv - w_len
            u_x, u_y = k * ux, k * uy
        else:
            lx, ly, qx2, qy2 = _legs(rpx, rpy, dist_sq, comb)
            if _det(rpx, rpy, w_x, w_y) > 0.0:
                dx, dy = lx, ly
            else:
                dx, dy = -qx2, -qy2
            proj = rvx * dx + rvy * dy
            u_x, u_y = proj * dx - rvx, proj * dy - rvy
    else:
        inv_dt = 1.0 / time_step
        w_x, w_y = rvx - inv_dt * rpx, rvy - inv_dt * rpy
        w_len = math.sqrt(w_x * w_x + w_y * w_y)
        ux, uy = w_x / w_len, w_y / w_len
        dx, dy = uy, -ux
        k = comb * inv_dt - w_len
        u_x, u_y = k * ux, k * uy
    return _add_line(lines, n, vx + share * u_x, vy + share * u_y, dx, dy)


@_jit
def _lp1(lines, no, radius, ox, oy, direction_opt):
    px, py, dx, dy = lines[no, 0], lines[no, 1], lines[no, 2], lines[no, 3]
    dot = px * dx + py * dy
    disc = dot * dot + radius * radius - (px * px + py * py)
    if disc < 0.0:
        return False, 0.0, 0.0
    sq = math.sqrt(disc)
    t_left, t_right = -dot - sq, -dot + sq
    for i in range(no):
        pix, piy, dix, diy = lines[i, 0], lines[i, 1], lines[i, 2], lines[i, 3]
        denom = _det(dx, dy, dix, diy)
        numer = _det(dix, diy, px - pix, py - piy)
        if abs(denom) <= EPS:
            if numer < 0.0:
                return False, 0.0, 0.0
            continue
        t = numer / denom
        if denom >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return False, 0.0, 0.0
    if direction_opt:
        t = t_right if ox * dx + oy * dy > 0.0 else t_left
        return True, px + t * dx, py + t * dy
    t = dx * (ox - px) + dy * (oy - py)
    t = min(max(t, t_left), t_right)
    return True, px + t * dx, py + t * dy


@_jit
def _lp2(lines, n, radius, ox, oy, direction_opt):
    if direction_opt:
        rx, ry = radius * ox, radius * oy
    elif ox * ox + oy * oy > radius * radius:
        norm = math.sqrt(ox * ox + oy * oy)
        rx, ry = ox / norm * radius, oy / norm * radius
    else:
        rx, ry = ox, oy
    for i in range(n):
        if _det(lines[i, 2], lines[i, 3], lines[i, 0] - rx, lines[i, 1] - ry) > 0.0:
            ok, nx, ny = _lp1(lines, i, radius, ox, oy, direction_opt)
            if not ok:
                return i, rx, ry
            rx, ry = nx, ny
    return n, rx, ry


@_jit
def _lp3(lines, n, n_obst, begin, radius, rx, ry, proj):
    distance = 0.0
    for i in range(begin, n):
        pix, piy, dix, diy = lines[i, 0], lines[i, 1], lines[i, 2], lines[i, 3]
        if _det(dix, diy, pix - rx, piy - ry) > distance:
            m = 0
            for j in range(n_obst):
                m = _add_line(proj, m, lines[j, 0], lines[j, 1], lines[j, 2], lines[j, 3])
            for j in range(n_obst, i):
                pjx, pjy, djx, djy = lines[j, 0], lines[j, 1], lines[j, 2], lines[j, 3]
                det = _det(dix, diy, djx, djy)
                if abs(det) <= EPS:
                    if dix * djx + diy * djy > 0.0:
                        continue
                    qx, qy = 0.5 * (pix + pjx), 0.5 * (piy + pjy)
                else:
                    k = _det(djx, djy, pix - pjx, piy - pjy) / det
                    qx, qy = pix + k * dix, piy + k * diy
                ex, ey = djx - dix, djy - diy
                norm = math.sqrt(ex * ex + ey * ey)
                m = _add_line(proj, m, qx, qy, ex / norm, ey / norm)
            fail, nx, ny = _lp2(proj, m, radius, -diy, dix, True)
            if fail == m:
                rx, ry = nx, ny
            distance = _det(dix, diy, pix - rx, piy - ry)
    return rx, ry


@_jit
def _keep_pace(lines, n, rx, ry, ox, oy, top):
    """ORCA's velocity (rx, ry) lengthened along its direction toward the preferred speed ``|(ox, oy)|``.

    Only for a velocity that still goes forward (within 90° of the preferred one) and is slower than
    preferred: the largest multiple, up to the preferred speed (and ``top``, the speed limit), that
    every line still allows. The lines are half-planes, so the allowed multiples form an interval
    holding 1; each line whose side the ray leaves caps it at ``det(d, p) / det(d, r)``.
    """
    want, have = min(math.sqrt(ox * ox + oy * oy), top), math.sqrt(rx * rx + ry * ry)
    if have <= EPS or have >= want or rx * ox + ry * oy <= 0.0:
        return rx, ry
    scale = want / have
    for i in range(n):
        slope = _det(lines[i, 2], lines[i, 3], rx, ry)
        if slope < 0.0:
            scale = min(scale, _det(lines[i, 2], lines[i, 3], lines[i, 0], lines[i, 1]) / slope)
    scale = max(scale, 1.0)
    return rx * scale, ry * scale


@_jit
def _agent_lines(i, pos, vel, radii, wall_radii, speeds, points, nxt, prv, dirs, convex, left_t, right_t, root,
                 neighbor_dist, max_neighbors, time_horizon, th_obst, time_step, static_full, lines, work, grid):  # fmt: skip
    """Agent i's ORCA lines into ``lines`` (obstacle lines first); returns (count, obstacle-line count).

    Walls use ``wall_radii[i]`` and agents ``radii`` (equal in RVO2; a crowd may keep a personal space
    larger than the body from other people only). With ``static_full`` an agent takes the whole
    avoidance against a neighbour whose speed limit is 0 (who cannot take its half), else RVO2's half.
    """
    found_v, found_d, stack, nb_idx, nb_d = work
    n = 0
    if points.shape[0] > 0:
        n = _obstacle_lines(pos[i], vel[i], wall_radii[i], speeds[i], points, nxt, prv, dirs, convex, left_t,
                            right_t, root, th_obst, lines, found_v, found_d, stack)  # fmt: skip
    n_obst = n
    count = _agent_neighbours(i, pos, neighbor_dist, max_neighbors, nb_idx, nb_d, grid)
    for k in range(count):
        j = nb_idx[k]
        share = 1.0 if static_full and speeds[j] == 0.0 else 0.5
        n = _agent_line(lines, n, pos[i, 0], pos[i, 1], vel[i, 0], vel[i, 1], radii[i], pos[j, 0], pos[j, 1],
                        vel[j, 0], vel[j, 1], radii[j], time_horizon, time_step, share)  # fmt: skip
    return n, n_obst


@_jit
def _work(n_vertices, max_neighbors):
    found_v = np.empty(max(n_vertices, 1), dtype=np.int64)
    found_d = np.empty(max(n_vertices, 1))
    stack = np.empty((2 * n_vertices + 2, 2), dtype=np.int64)
    return found_v, found_d, stack, np.empty(max_neighbors, dtype=np.int64), np.empty(max_neighbors)


@_jit
def step_kernel(pos, vel, pref, radii, wall_radii, speeds, points, nxt, prv, dirs, convex, left_t, right_t, root,
                neighbor_dist, max_neighbors, time_horizon, th_obst, time_step, static_full, keep_pace):  # fmt: skip
    """New (N, 2) velocities: every agent's lines, then linearProgram2 (and 3 where 2 is infeasible).

    With ``keep_pace`` a feasible answer slower than preferred is then lengthened (:func:`_keep_pace`).
    An agent whose speed limit is 0 (someone standing) gets 0 without its programs: no velocity within a
    circle of radius 0 is anything else, and in a dense crowd most of the agents stand.
    """
    n_agents, n_vertices = pos.shape[0], points.shape[0]
    out = np.zeros((n_agents, 2))
    size = n_vertices + max_neighbors + 1
    lines = np.empty((size, 4))
    proj = np.empty((size, 4))
    work = _work(n_vertices, max_neighbors)
    grid = agent_grid(pos, neighbor_dist)
    for i in range(n_agents):
        if speeds[i] <= 0.0:
            continue
        n, n_obst = _agent_lines(i, pos, vel, radii, wall_radii, speeds, points, nxt, prv, dirs, convex, left_t,
                                 right_t, root, neighbor_dist, max_neighbors, time_horizon, th_obst, time_step,
                                 static_full, lines, work, grid)  # fmt: skip
        fail, rx, ry = _lp2(lines, n, speeds[i], pref[i, 0], pref[i, 1], False)
        if fail < n:
            rx, ry = _lp3(lines, n, n_obst, fail, speeds[i], rx, ry, proj)
        elif keep_pace:
            rx, ry = _keep_pace(lines, n, rx, ry, pref[i, 0], pref[i, 1], speeds[i])
        out[i, 0], out[i, 1] = rx, ry
    return out


@_jit
def lines_kernel(pos, vel, radii, wall_radii, speeds, points, nxt, prv, dirs, convex, left_t, right_t, root,
                 neighbor_dist, max_neighbors, time_horizon, th_obst, time_step, static_full, keep_pace):  # fmt: skip
    """Every agent's ORCA lines: ``(lines (N, L, 4) [px, py, dx, dy], counts (N,), obstacle counts (N,))``.

    Takes :func:`step_kernel`'s arguments but the preferred velocities; ``keep_pace`` does not change the lines.
    """
    n_agents, n_vertices = pos.shape[0], points.shape[0]
    size = n_vertices + max_neighbors + 1
    lines = np.zeros((n_agents, size, 4))
    counts = np.zeros(n_agents, dtype=np.int64)
    n_obstacle = np.zeros(n_agents, dtype=np.int64)
    work = _work(n_vertices, max_neighbors)
    grid = agent_grid(pos, neighbor_dist)
    for i in range(n_agents):
        counts[i], n_obstacle[i] = _agent_lines(i, pos, vel, radii, wall_radii, speeds, points, nxt, prv, dirs,
                                                convex, left_t, right_t, root, neighbor_dist, max_neighbors,
                                                time_horizon, th_obst, time_step, static_full, lines[i],
                                                work, grid)  # fmt: skip
    return lines, counts, n_obstacle
