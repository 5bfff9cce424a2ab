"""Compiled (numba) navmesh queries and build steps for :mod:`song.geometry.navmesh`.

A path query is a few hundred scalar tests (point location, line-of-sight rays against nearby walls,
an A* over the visibility graph); as numpy calls each costs microseconds of dispatch, which made a query
2–67 ms where Detour takes 0.05 ms. Written as scalar loops over flat arrays they run at C speed. The
plain numpy implementation is kept in :mod:`song.geometry._navmesh_reference` as the reference twin.

Spatial look-ups use a uniform hash of ``bucket`` m cells stored in CSR form (``start`` (C + 1),
``items``); walls are hashed by their bounding box grown by a margin, so a ray that walks the cells
it passes (Amanatides–Woo) meets every wall it can touch, even across cell corners and rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from song.geometry._astar_kernel import heap_pop, heap_push, heap_reserve

TOUCH_EPS = 1e-12  # |cross| below this (m²) counts as collinear (coordinates are ≤ 1 km)
SHORTEN_M = 1e-7  # a move test's segment is shortened by this at both ends (see segments_clear)
NUDGE_M = 1e-6  # boundary points are moved this far into their triangle


def _jit(fn):
    return numba.njit(cache=True, nogil=True)(fn)


@_jit
def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


@_jit
def _zero(v):
    return 0.0 if abs(v) < TOUCH_EPS else v


@_jit
def _blocked(px, py, qx, qy, ax, ay, bx, by, ends_on_mesh):
    """Segment p→q hits wall a→b: it crosses the wall, or the wall's end touches the segment's inside.

    With ``ends_on_mesh`` (both ends are mesh points, as in every line-of-sight test), an end of the
    segment lying on the wall is no hit: a segment that left the mesh there would have to cross another
    wall to reach its other end. Without it (a move toward any target), touching counts as a hit.
    Collinear overlap is never a hit (a path may run along a wall).
    """
    dx, dy = qx - px, qy - py
    ex, ey = bx - ax, by - ay
    o1 = _zero(_cross(dx, dy, ax - px, ay - py))
    o2 = _zero(_cross(dx, dy, bx - px, by - py))
    if o1 == 0.0 and o2 == 0.0:
        return False
    o3 = _zero(_cross(ex, ey, px - ax, py - ay))
    o4 = _zero(_cross(ex, ey, qx - ax, qy - ay))
    if ends_on_mesh:
        return o1 * o2 <= 0.0 and o3 * o4 < 0.0
    return o1 * o2 <= 0.0 and o3 * o4 <= 0.0


# ---- spatial hash ---------------------------------------------------------------------------------
def hash_boxes(lo: np.ndarray, hi: np.ndarray, origin: np.ndarray, n: np.ndarray, bucket: float):
    """CSR hash of boxes: ``(start (C + 1), items)``, items of cell c in ``items[start[c]:start[c + 1]]``.

    Cell c = row * n[0] + column; boxes (M, 2) lo/hi in metres; ids within a cell are ascending.
    """
    i0 = np.clip(np.floor((lo - origin) / bucket).astype(np.int64), 0, n - 1)
    i1 = np.clip(np.floor((hi - origin) / bucket).astype(np.int64), 0, n - 1)
    nx, ny = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
    count = nx * ny
    item = np.repeat(np.arange(len(lo)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    cell = (i0[item, 1] + k // nx[item]) * n[0] + i0[item, 0] + k % nx[item]
    order = np.lexsort((item, cell))
    per = np.bincount(cell, minlength=int(n.prod()))
    start = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    return start, item[order].astype(np.int64)


@_jit
def _cell(x, y, ox, oy, nx, ny, bucket):
    i = min(max(int(math.floor((x - ox) / bucket)), 0), nx - 1)
    j = min(max(int(math.floor((y - oy) / bucket)), 0), ny - 1)
    return i, j


# ---- rays -----------------------------------------------------------------------------------------
@_jit
def _ray_clear(px, py, qx, qy, va, vb, verts, hgrid, hstart, hitems, stamp, tick, ends_on_mesh=True, shorten=0.0):
    """Segment p→q stays on the mesh: it hits no wall (walls va[k]→vb[k] as vertex ids, see :func:`_blocked`).

    The segment is first shortened by ``shorten`` m at both ends; stamps equal to ``tick`` mark walls
    already tested for this segment.
    """
    dx, dy = qx - px, qy - py
    length = math.hypot(dx, dy)
    s = min(shorten, 0.5 * length)
    if length > 0.0 and s > 0.0:
        px, py = px + dx / length * s, py + dy / length * s
        qx, qy = qx - dx / length * s, qy - dy / length * s
    ox, oy, bucket = hgrid[0], hgrid[1], hgrid[2]
    nx, ny = int(hgrid[3]), int(hgrid[4])
    ix, iy = _cell(px, py, ox, oy, nx, ny, bucket)
    ex, ey = _cell(qx, qy, ox, oy, nx, ny, bucket)
    cx, cy = (px - ox) / bucket, (py - oy) / bucket
    ddx, ddy = (qx - px) / bucket, (qy - py) / bucket
    step_x = 1 if ddx > 0.0 else -1
    step_y = 1 if ddy > 0.0 else -1
    t_x = ((ix + 1 - cx) / ddx if ddx > 0.0 else (ix - cx) / ddx) if ddx != 0.0 else np.inf
    t_y = ((iy + 1 - cy) / ddy if ddy > 0.0 else (iy - cy) / ddy) if ddy != 0.0 else np.inf
    dt_x = abs(1.0 / ddx) if ddx != 0.0 else np.inf
    dt_y = abs(1.0 / ddy) if ddy != 0.0 else np.inf
    steps = abs(ex - ix) + abs(ey - iy)
    for _ in range(steps + 1):
        c = iy * nx + ix
        for m in range(hstart[c], hstart[c + 1]):
            k = hitems[m]
            if stamp[k] == tick:
                continue
            stamp[k] = tick
            a, b = va[k], vb[k]
            if _blocked(px, py, qx, qy, verts[a, 0], verts[a, 1], verts[b, 0], verts[b, 1], ends_on_mesh):
                return False
        if ix == ex and iy == ey:
            break
        if t_x < t_y:
            ix = min(max(ix + step_x, 0), nx - 1)
            t_x += dt_x
        else:
            iy = min(max(iy + step_y, 0), ny - 1)
            t_y += dt_y
    if ix != ex or iy != ey:  # rounding left the walk short of the end cell: test it too
        c = ey * nx + ex
        for m in range(hstart[c], hstart[c + 1]):
            k = hitems[m]
            if stamp[k] != tick:
                stamp[k] = tick
                a, b = va[k], vb[k]
                if _blocked(px, py, qx, qy, verts[a, 0], verts[a, 1], verts[b, 0], verts[b, 1], ends_on_mesh):
                    return False
    return True


@_jit
def segments_clear(p, q, va, vb, verts, hgrid, hstart, hitems):
    """(N,) bool: each segment p[i]→q[i] hits no wall, touching counted as a hit (the crowd's move test).

    Segments are shortened by ``SHORTEN_M`` at both ends, so touching an end point's own walls is no hit.
    """
    stamp = np.zeros(len(va), dtype=np.int64)
    out = np.empty(len(p), dtype=np.bool_)
    for i in range(len(p)):
        a, b = p[i], q[i]
        out[i] = _ray_clear(
            a[0], a[1], b[0], b[1], va, vb, verts, hgrid, hstart, hitems, stamp, i + 1, False, SHORTEN_M
        )
    return out


@_jit
def _tangent(v, ox, oy, verts, prev, nxt):
    """The line from boundary vertex v to point o leaves both of v's walls on one side."""
    x, y = verts[v, 0], verts[v, 1]
    dx, dy = ox - x, oy - y
    s1 = _zero(_cross(dx, dy, verts[prev[v], 0] - x, verts[prev[v], 1] - y))
    s2 = _zero(_cross(dx, dy, verts[nxt[v], 0] - x, verts[nxt[v], 1] - y))
    return s1 * s2 >= 0.0


@_jit
def visibility_edges(reflex, verts, prev, nxt, va, vb, hgrid, hstart, hitems):
    """(E, 2) pairs i < j of reflex positions joined by a bitangent segment that stays on the mesh."""
    r = len(reflex)
    stamp = np.zeros(len(va), dtype=np.int64)
    out = np.empty((max(16, 4 * r), 2), dtype=np.int64)
    n, tick = 0, 0
    for i in range(r):
        vi = reflex[i]
        for j in range(i + 1, r):
            vj = reflex[j]
            if not _tangent(vi, verts[vj, 0], verts[vj, 1], verts, prev, nxt):
                continue
            if not _tangent(vj, verts[vi, 0], verts[vi, 1], verts, prev, nxt):
                continue
            tick += 1
            if not _ray_clear(
                verts[vi, 0],
                verts[vi, 1],
                verts[vj, 0],
                verts[vj, 1],
                va,
                vb,
                verts,
                hgrid,
                hstart,
                hitems,
                stamp,
                tick,
            ):
                continue
            if n == len(out):
                out = np.concatenate((out, np.empty_like(out)))
            out[n, 0], out[n, 1] = i, j
            n += 1
    return out[:n].copy()


# ---- point location -------------------------------------------------------------------------------
@_jit
def _locate_one(x, y, tol, verts, tris, tgrid, tstart, titems):
    ox, oy, bucket = tgrid[0], tgrid[1], tgrid[2]
    i, j = _cell(x, y, ox, oy, int(tgrid[3]), int(tgrid[4]), bucket)
    c = j * int(tgrid[3]) + i
    for m in range(tstart[c], tstart[c + 1]):
        t = titems[m]
        inside = True
        for k in range(3):
            a, b = tris[t, k], tris[t, (k + 1) % 3]
            ex, ey = verts[b, 0] - verts[a, 0], verts[b, 1] - verts[a, 1]
            length = max(math.hypot(ex, ey), 1e-300)
            if _cross(ex, ey, x - verts[a, 0], y - verts[a, 1]) / length < -tol:
                inside = False
                break
        if inside:
            return t
    return -1


@_jit
def locate(points, tol, verts, tris, tgrid, tstart, titems):
    """(N,) triangle containing each point (the first in id order), or -1."""
    out = np.empty(len(points), dtype=np.int64)
    for i in range(len(points)):
        out[i] = _locate_one(points[i, 0], points[i, 1], tol, verts, tris, tgrid, tstart, titems)
    return out


@_jit
def _nearest_wall(x, y, va, vb, verts, only, comp_of_seg):
    """Closest wall point to (x, y): (cx, cy, distance, wall id); walls of component ``only`` if ≥ 0."""
    best, bx, by, bk = np.inf, x, y, -1
    for k in range(len(va)):
        if only >= 0 and comp_of_seg[k] != only:
            continue
        ax, ay = verts[va[k], 0], verts[va[k], 1]
        dx, dy = verts[vb[k], 0] - ax, verts[vb[k], 1] - ay
        t = ((x - ax) * dx + (y - ay) * dy) / max(dx * dx + dy * dy, 1e-300)
        t = min(max(t, 0.0), 1.0)
        cx, cy = ax + t * dx, ay + t * dy
        d = math.hypot(x - cx, y - cy)
        if d < best:
            best, bx, by, bk = d, cx, cy, k
    return bx, by, best, bk


@_jit
def _nudge(x, y, k, verts, tris, seg_tri):
    """Move a boundary point NUDGE_M toward the centroid of its wall's triangle."""
    t = seg_tri[k]
    cx = (verts[tris[t, 0], 0] + verts[tris[t, 1], 0] + verts[tris[t, 2], 0]) / 3.0
    cy = (verts[tris[t, 0], 1] + verts[tris[t, 1], 1] + verts[tris[t, 2], 1]) / 3.0
    dx, dy = cx - x, cy - y
    d = max(math.hypot(dx, dy), 1e-300)
    return x + dx / d * NUDGE_M, y + dy / d * NUDGE_M


@_jit
def snap(points, max_dist, verts, tris, seg_tri, va, vb, tgrid, tstart, titems):
    """Nearest mesh point of each point: ``(snapped (N, 2), triangle (N,) or -1, moved (N,))``."""
    n = len(points)
    out = points.copy()
    tri = np.empty(n, dtype=np.int64)
    moved = np.zeros(n)
    dummy = np.zeros(0, dtype=np.int64)
    for i in range(n):
        x, y = points[i, 0], points[i, 1]
        t = _locate_one(x, y, 1e-9, verts, tris, tgrid, tstart, titems)
        if t < 0 and len(va) > 0:
            cx, cy, d, k = _nearest_wall(x, y, va, vb, verts, -1, dummy)
            if d <= max_dist:
                out[i, 0], out[i, 1] = _nudge(cx, cy, k, verts, tris, seg_tri)
                moved[i] = d
                t = seg_tri[k]
            else:
                moved[i] = np.inf
        elif t < 0:
            moved[i] = np.inf
        tri[i] = t
    return out, tri, moved


# ---- shortest paths -------------------------------------------------------------------------------
@_jit
def _visible_from(x, y, reflex, verts, prev, nxt, va, vb, hgrid, hstart, hitems, stamp, tick):
    """Per reflex position: distance from (x, y) along a tangent, unobstructed line, else inf."""
    r = len(reflex)
    dist = np.full(r, np.inf)
    for i in range(r):
        v = reflex[i]
        if not _tangent(v, x, y, verts, prev, nxt):
            continue
        tick += 1
        if _ray_clear(x, y, verts[v, 0], verts[v, 1], va, vb, verts, hgrid, hstart, hitems, stamp, tick):
            dist[i] = math.hypot(verts[v, 0] - x, verts[v, 1] - y)
    return dist, tick


@_jit
def shortest_path(sx, sy, gx, gy, reflex, verts, prev, nxt, va, vb, hgrid, hstart, hitems, vptr, vidx, vlen):
    """Exact shortest path between two points of one mesh part: A* over the reduced visibility graph.

    Shortest paths in a polygonal domain bend only at reflex vertices, on bitangent edges; the graph's
    edges between reflex vertices are precomputed (``vptr``/``vidx``/``vlen``: CSR adjacency with
    lengths). The start's and goal's edges are checked lazily, as in Lazy Theta*: every reflex vertex
    tangent from the start enters the heap with its straight-line cost, and the ray is cast only when
    it is popped (if blocked, its cost is re-derived from its already expanded neighbours); the ray to
    the goal is cast only from expanded vertices tangent to it. The heuristic (straight-line distance
    to the goal) is consistent, so the first time the goal leaves the heap its cost is optimal.

    Returns:
        (K,) int64 reflex positions the path bends at (empty for a straight path), or a single -1
        when no path exists.
    """
    stamp = np.zeros(len(va), dtype=np.int64)
    if _ray_clear(sx, sy, gx, gy, va, vb, verts, hgrid, hstart, hitems, stamp, 1):
        return np.zeros(0, dtype=np.int64)
    tick = 1
    r = len(reflex)
    goal, start = r, -2
    g = np.full(r + 1, np.inf)
    parent = np.full(r + 1, -1, dtype=np.int64)
    closed = np.zeros(r + 1, dtype=np.bool_)
    heap = np.empty((64, 2))
    size = 0
    for i in range(r):
        v = reflex[i]
        if _tangent(v, sx, sy, verts, prev, nxt):
            g[i] = math.hypot(verts[v, 0] - sx, verts[v, 1] - sy)
            parent[i] = start
            h = math.hypot(verts[v, 0] - gx, verts[v, 1] - gy)
            heap = heap_reserve(heap, size)
            size = heap_push(heap, size, g[i] + h, i)
    while size > 0:
        f, u, size = heap_pop(heap, size)
        if u == goal:
            break
        if closed[u]:
            continue
        vx, vy = verts[reflex[u], 0], verts[reflex[u], 1]
        hu = math.hypot(vx - gx, vy - gy)
        if f > g[u] + hu + 1e-9:
            continue  # stale entry
        if parent[u] == start:
            tick += 1
            if not _ray_clear(sx, sy, vx, vy, va, vb, verts, hgrid, hstart, hitems, stamp, tick):
                g[u], parent[u] = np.inf, -1  # the start cannot see u: its best expanded neighbour instead
                for m in range(vptr[u], vptr[u + 1]):
                    w = vidx[m]
                    if closed[w] and g[w] + vlen[m] < g[u]:
                        g[u], parent[u] = g[w] + vlen[m], w
                if g[u] < np.inf:
                    heap = heap_reserve(heap, size)
                    size = heap_push(heap, size, g[u] + hu, u)
                continue
        closed[u] = True
        if g[u] + hu < g[goal] and _tangent(reflex[u], gx, gy, verts, prev, nxt):
            tick += 1
            if _ray_clear(vx, vy, gx, gy, va, vb, verts, hgrid, hstart, hitems, stamp, tick):
                g[goal], parent[goal] = g[u] + hu, u
                heap = heap_reserve(heap, size)
                size = heap_push(heap, size, g[goal], goal)
        for m in range(vptr[u], vptr[u + 1]):
            w = vidx[m]
            cand = g[u] + vlen[m]
            if cand < g[w]:
                g[w] = cand
                parent[w] = u
                h = math.hypot(verts[reflex[w], 0] - gx, verts[reflex[w], 1] - gy)
                heap = heap_reserve(heap, size)
                size = heap_push(heap, size, cand + h, w)
    if g[goal] == np.inf:
        return np.full(1, -1, dtype=np.int64)
    chain = np.empty(r + 1, dtype=np.int64)
    n, u = 0, parent[goal]
    while u >= 0:
        chain[n] = u
        n += 1
        u = parent[u]
    return chain[:n][::-1].copy()


@_jit
def distances_from(sx, sy, goals, reflex, verts, prev, nxt, va, vb, hgrid, hstart, hitems, vptr, vidx, vlen):
    """(N,) exact shortest-path lengths from one point to many (one Dijkstra over the visibility graph)."""
    stamp = np.zeros(len(va), dtype=np.int64)
    r = len(reflex)
    g, tick = _visible_from(sx, sy, reflex, verts, prev, nxt, va, vb, hgrid, hstart, hitems, stamp, 0)
    done = np.zeros(r, dtype=np.bool_)
    heap = np.empty((64, 2))
    size = 0
    for i in range(r):
        if g[i] < np.inf:
            heap = heap_reserve(heap, size)
            size = heap_push(heap, size, g[i], i)
    while size > 0:
        f, u, size = heap_pop(heap, size)
        if done[u]:
            continue
        done[u] = True
        for m in range(vptr[u], vptr[u + 1]):
            w = vidx[m]
            cand = g[u] + vlen[m]
            if cand < g[w]:
                g[w] = cand
                heap = heap_reserve(heap, size)
                size = heap_push(heap, size, cand, w)
    out = np.full(len(goals), np.inf)
    for k in range(len(goals)):
        gx, gy = goals[k, 0], goals[k, 1]
        tick += 1
        if _ray_clear(sx, sy, gx, gy, va, vb, verts, hgrid, hstart, hitems, stamp, tick):
            out[k] = math.hypot(gx - sx, gy - sy)
            continue
        to_goal, tick = _visible_from(gx, gy, reflex, verts, prev, nxt, va, vb, hgrid, hstart, hitems, stamp, tick)
        best = np.inf
        for i in range(r):
            if g[i] + to_goal[i] < best:
                best = g[i] + to_goal[i]
        out[k] = best
    return out


# ---- triangulation repair -------------------------------------------------------------------------
@_jit
def split_t_junctions(verts, tris, tol):
    """Split triangles whose edges pass through another vertex, so that neighbours share vertex pairs.

    Earcut returns zero-area triangles where ring vertices are collinear; dropping them leaves a
    T-junction (one side of an edge split at a vertex, the other not), and neighbour search by shared
    vertex pairs then misses the link: the mesh falls apart into parts that touch along an edge. Each
    edge with a vertex strictly inside it (within ``tol`` m of the line) is split there, the triangle
    fanned from its opposite corner; repeated until no edge holds a vertex.

    Returns:
        (T', 3) int64 triangles, same orientation.
    """
    order = np.argsort(verts[:, 0])
    xs = verts[order, 0]
    cur = tris.copy()
    for _ in range(64):
        out = np.empty((len(cur) * 3 + 16, 3), dtype=np.int64)
        n, changed = 0, False
        for t in range(len(cur)):
            split = False
            for k in range(3):
                a, b, c = cur[t, k], cur[t, (k + 1) % 3], cur[t, (k + 2) % 3]
                ax, ay, bx, by = verts[a, 0], verts[a, 1], verts[b, 0], verts[b, 1]
                ex, ey = bx - ax, by - ay
                len2 = ex * ex + ey * ey
                if len2 <= 0.0:
                    continue
                length = math.sqrt(len2)
                lo = np.searchsorted(xs, min(ax, bx) - tol)
                hi = np.searchsorted(xs, max(ax, bx) + tol, side="right")
                best_t, best_v = 2.0, -1
                for m in range(lo, hi):
                    v = order[m]
                    if v == a or v == b or v == c:
                        continue
                    px, py = verts[v, 0] - ax, verts[v, 1] - ay
                    if abs(_cross(ex, ey, px, py)) / length > tol:
                        continue
                    s = (px * ex + py * ey) / len2
                    if s * length > tol and (1.0 - s) * length > tol and s < best_t:
                        best_t, best_v = s, v
                if best_v >= 0:  # split at the vertex nearest a; the next pass splits the rest
                    if n + 2 > len(out):
                        out = np.concatenate((out, np.empty_like(out)))
                    out[n, 0], out[n, 1], out[n, 2] = a, best_v, c
                    out[n + 1, 0], out[n + 1, 1], out[n + 1, 2] = best_v, b, c
                    n += 2
                    split = changed = True
                    break
            if not split:
                if n + 1 > len(out):
                    out = np.concatenate((out, np.empty_like(out)))
                out[n] = cur[t]
                n += 1
        cur = out[:n].copy()
        if not changed:
            break
    return cur


@_jit
def nearest_walls(points, va, vb, verts):
    """Closest wall point to each point: ``(closest (N, 2), distance (N,), wall id (N,))``."""
    n = len(points)
    closest = np.empty((n, 2))
    dist = np.empty(n)
    wall = np.empty(n, dtype=np.int64)
    dummy = np.zeros(0, dtype=np.int64)
    for i in range(n):
        cx, cy, d, k = _nearest_wall(points[i, 0], points[i, 1], va, vb, verts, -1, dummy)
        closest[i, 0], closest[i, 1], dist[i], wall[i] = cx, cy, d, k
    return closest, dist, wall


@_jit
def nearest_wall_of(x, y, only, comp_of_seg, va, vb, verts, tris, seg_tri):
    """The point of component ``only``'s walls nearest (x, y), nudged inside: ``(x, y, wall id)``."""
    cx, cy, _, k = _nearest_wall(x, y, va, vb, verts, only, comp_of_seg)
    if k < 0:
        return x, y, k
    nx_, ny_ = _nudge(cx, cy, k, verts, tris, seg_tri)
    return nx_, ny_, k


@_jit
def constrain_moves(pos, target, va, vb, verts, tris, seg_tri, hgrid, hstart, hitems):
    """Moves whose segment leaves the mesh end at the mesh point nearest their target (nudged inside)."""
    stamp = np.zeros(len(va), dtype=np.int64)
    out = target.copy()
    dummy = np.zeros(0, dtype=np.int64)
    for i in range(len(pos)):
        px, py, qx, qy = pos[i, 0], pos[i, 1], target[i, 0], target[i, 1]
        if _ray_clear(px, py, qx, qy, va, vb, verts, hgrid, hstart, hitems, stamp, i + 1, False):
            continue  # a target on a wall's line counts as leaving: it may be a hair outside
        cx, cy, _, k = _nearest_wall(target[i, 0], target[i, 1], va, vb, verts, -1, dummy)
        out[i, 0], out[i, 1] = _nudge(cx, cy, k, verts, tris, seg_tri)
    return out


OK, PARTIAL, UNREACHABLE, START_OFF, GOAL_OFF, NO_PATH = 0, 1, 2, 3, 4, 5


@_jit
def find_path(sx, sy, gx, gy, max_snap, allow_partial, m):
    """A whole path query: snap both ends, check their mesh parts, then :func:`shortest_path`.

    ``m`` is the mesh's tuple of kernel arrays (``Navmesh._kernel_args``). Returns ``(status code,
    corner points (K, 2), length)``; codes are the module's OK … NO_PATH.
    """
    verts, tris, seg_tri, seg_comp, va, vb, reflex, prev, nxt, comp = (
        m[0],
        m[1],
        m[2],
        m[3],
        m[4],
        m[5],
        m[6],
        m[7],
        m[8],
        m[9],
    )
    tgrid, tstart, titems, sgrid, sstart, sitems, vptr, vidx, vlen = (
        m[10],
        m[11],
        m[12],
        m[10],
        m[13],
        m[14],
        m[15],
        m[16],
        m[17],
    )
    ends = np.empty((2, 2))
    ends[0, 0], ends[0, 1], ends[1, 0], ends[1, 1] = sx, sy, gx, gy
    snapped, tri, _ = snap(ends, max_snap, verts, tris, seg_tri, va, vb, tgrid, tstart, titems)
    none = np.zeros((0, 2))
    if tri[0] < 0:
        return START_OFF, none, np.inf
    if tri[1] < 0:
        return GOAL_OFF, none, np.inf
    code = OK
    if comp[tri[0]] != comp[tri[1]]:
        if not allow_partial:
            return UNREACHABLE, none, np.inf
        x, y, k = nearest_wall_of(snapped[1, 0], snapped[1, 1], comp[tri[0]], seg_comp, va, vb, verts, tris, seg_tri)
        snapped[1, 0], snapped[1, 1] = x, y
        code = PARTIAL
    ax, ay, bx, by = snapped[0, 0], snapped[0, 1], snapped[1, 0], snapped[1, 1]
    bends = shortest_path(ax, ay, bx, by, reflex, verts, prev, nxt, va, vb, sgrid, sstart, sitems, vptr, vidx, vlen)
    if len(bends) == 1 and bends[0] < 0:
        return NO_PATH, none, np.inf
    pts = np.empty((len(bends) + 2, 2))
    pts[0, 0], pts[0, 1] = ax, ay
    for i in range(len(bends)):
        pts[i + 1, 0], pts[i + 1, 1] = verts[reflex[bends[i]], 0], verts[reflex[bends[i]], 1]
    pts[-1, 0], pts[-1, 1] = bx, by
    length = 0.0
    for i in range(len(pts) - 1):
        length += math.hypot(pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1])
    return code, pts, length
