"""Compiled (numba) pieces of the crowd simulation's frame step.

At indoor crowd sizes (tens of pedestrians) a frame's arithmetic is small: as numpy and navmesh calls,
the frame cost ~300 µs, almost all of it dispatch. A frame is now a handful of compiled calls (the
avoidance inputs, the avoidance model, the settled moves, progress, the record) with Python left for
what is rare (corner look-ahead checks, replans, stops). The reference twins live in
:mod:`song.pipeline.crowd._simulate_reference`.
"""

from __future__ import annotations

import numba
import numpy as np

from song.geometry import _navmesh_kernel as _nk

HEADING_SMOOTHING = 0.15  # EMA weight of the newest velocity in the heading estimate
STAND_SPEED = 0.05  # m/s: below this the heading is held


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
    target: np.ndarray, moving: np.ndarray, radius: np.ndarray, margin: float
) -> tuple[np.ndarray, bool]:  # pragma: no cover
    """Pushes (N, 2) m separating overlapping pairs to their bodies' radii + ``margin``, and whether any pair overlaps.

    A walker moves half the overlap with another walker and all of it with someone standing; a
    standing pedestrian is not pushed, so two people standing too close (one who gave up, stepped
    aside) do not count (they would keep every frame running all its passes while pushing nobody).
    """
    n = len(target)
    push = np.zeros((n, 2))
    found = False
    for i in range(n):
        if not moving[i]:
            continue
        for j in range(n):
            if i == j:
                continue
            dx, dy = target[i, 0] - target[j, 0], target[i, 1] - target[j, 1]
            dist = np.hypot(dx, dy)
            overlap = radius[i] + radius[j] + margin - dist
            if overlap <= 0.0:
                continue
            found = True
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
    ``2 · radius`` (N,) of the goal and never overshoots it in one step ``dt``.
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
        desired = speed[i] * min(1.0, d_goal / (2.0 * radius[i]))
        if not has_next[i]:
            desired = min(desired, len0 / dt)
        norm = max(np.hypot(sx, sy), 1e-9)
        pref[i, 0], pref[i, 1] = sx / norm * desired, sy / norm * desired
    return pref


@numba.njit(cache=True, nogil=True)
def _on_mesh(x, y, tol, va, vb, verts, tris, tgrid, tstart, titems):  # pragma: no cover
    """The point is on the mesh within ``tol`` m (``Navmesh.contains``)."""
    if _nk._locate_one(x, y, tol, verts, tris, tgrid, tstart, titems) >= 0:
        return True
    if len(va) == 0:
        return False
    return _nk._nearest_wall(x, y, va, vb, verts, -1, np.zeros(0, dtype=np.int64))[2] <= tol


@numba.njit(cache=True, nogil=True)
def _constrain(px, py, qx, qy, stamp, tick, va, vb, verts, tris, seg_tri, hgrid, hstart, hitems):  # pragma: no cover
    """One move p→q kept on the mesh (``Navmesh.constrain_moves``)."""
    if _nk._ray_clear(px, py, qx, qy, va, vb, verts, hgrid, hstart, hitems, stamp, tick, False):
        return qx, qy
    cx, cy, _, k = _nk._nearest_wall(qx, qy, va, vb, verts, -1, np.zeros(0, dtype=np.int64))
    return _nk._nudge(cx, cy, k, verts, tris, seg_tri)


@numba.njit(cache=True, nogil=True)
def accelerate(vx, vy, wx, wy, limit, turn_limit=-1.0):  # pragma: no cover
    """One frame's velocity from ``(vx, vy)`` toward the wanted ``(wx, wy)``: ``(new vx, new vy)``.

    A walker under way that turns by at most 90° keeps its speed through the turn: its heading turns as
    fast as a sideways acceleration of ``turn_limit`` per frame allows (``turn_limit / speed`` radians a
    frame; ``limit`` when negative) and its speed changes by at most ``limit``. Otherwise (setting off,
    stopping, turning back) the change of the velocity vector is clamped to ``limit``: it slows down and
    sets off the other way. (Clamping the
    vector change in a turn too cuts across the circle: a 45° swerve at 1.3 m/s dipped to 1.2 m/s, a 90°
    one to 0.92 m/s; docs/crowd.md.)
    """
    s0, s1 = np.hypot(vx, vy), np.hypot(wx, wy)
    sideways = limit if turn_limit < 0.0 else turn_limit
    if s0 > limit and s1 > limit:  # under way, and staying so
        heading = np.arctan2(vy, vx)
        rest = (np.arctan2(wy, wx) - heading + np.pi) % (2.0 * np.pi) - np.pi  # the turn wanted, in [-pi, pi)
        if abs(rest) <= 0.5 * np.pi:
            turn = min(max(rest, -sideways / s0), sideways / s0)
            s = min(max(s1, s0 - limit), s0 + limit)
            return s * np.cos(heading + turn), s * np.sin(heading + turn)
    dvx, dvy = wx - vx, wy - vy
    norm = np.hypot(dvx, dvy)
    if norm > limit:
        dvx, dvy = dvx / norm * limit, dvy / norm * limit
    return vx + dvx, vy + dvy


@numba.njit(cache=True, nogil=True)
def _move(px, py, qx, qy, limit, stamp, tick, mesh):  # pragma: no cover
    """One step p→q kept on the mesh (sliding along walls) and no longer than ``limit``: ``(x, y, tick)``.

    Sliding along a non-convex wall can lengthen a step a little: it is shortened back along its
    direction, or cancelled when the shortened one would leave the mesh.
    """
    va, vb, verts, tris, seg_tri, hgrid, hstart, hitems, tgrid, tstart, titems = mesh
    tick += 1
    x, y = _constrain(px, py, qx, qy, stamp, tick, va, vb, verts, tris, seg_tri, hgrid, hstart, hitems)
    size = np.hypot(x - px, y - py)
    if not size > limit * (1 + 1e-9):  # rounding alone is not a violation
        return x, y, tick
    sx, sy = px + (x - px) * limit / size, py + (y - py) * limit / size
    tick += 1
    clear = _nk._ray_clear(px, py, sx, sy, va, vb, verts, hgrid, hstart, hitems, stamp, tick, False, _nk.SHORTEN_M)
    if clear and _on_mesh(sx, sy, 1e-9, va, vb, verts, tris, tgrid, tstart, titems):  # may end on an edge
        return sx, sy, tick
    return px, py, tick


@numba.njit(cache=True, nogil=True)
def settle_moves(
    pos, vel, rows, wanted, moving, speed, dt, accel_limit, radius, margin, passes, mesh, turn_limit=-1.0
):  # pragma: no cover
    """The frame's moves from the avoidance model's velocities: ``(new positions (N, 2), velocities (N, 2))``.

    ``wanted`` (M, 2) are the new velocities of pedestrians ``rows`` (M,); the others' are 0.

    In order: the acceleration limit (:func:`accelerate`); moves kept on the mesh and within the speed
    limit (:func:`_move`); up to ``passes`` overlap resolution passes (:func:`overlap_push`: bodies of
    ``radius`` (N,) kept ``margin`` apart, within each
    walker's speed budget, again through :func:`_move`). Each move is final when the passes see it (a
    step shortened or cancelled after them could leave a follower pressed 1 cm into a walker stopped
    that way). Non-walkers stay put.
    ``mesh`` is the navmesh kernel tuple ``(va, vb, verts, tris, seg_tri, hgrid, hstart, hitems, tgrid,
    tstart, titems)``. One compiled call per frame: as numpy and navmesh calls these were ~20 dispatches
    a frame. The reference twin is :func:`song.pipeline.crowd._simulate_reference.settle_moves_reference`.
    """
    n = len(pos)
    stamp = np.zeros(len(mesh[0]), dtype=np.int64)
    tick = 0
    target = pos.copy()
    full = np.zeros((n, 2))
    for m in range(len(rows)):
        full[rows[m], 0], full[rows[m], 1] = wanted[m, 0], wanted[m, 1]
    for i in range(n):
        if not moving[i]:
            continue
        vx, vy = accelerate(vel[i, 0], vel[i, 1], full[i, 0], full[i, 1], accel_limit, turn_limit)
        target[i, 0], target[i, 1], tick = _move(pos[i, 0], pos[i, 1], pos[i, 0] + vx * dt, pos[i, 1] + vy * dt,
                                                 speed[i] * dt, stamp, tick, mesh)  # fmt: skip
    for _ in range(passes):
        push, found = overlap_push(target, moving, radius, margin)
        if not found:
            break
        for i in range(n):
            if not moving[i] or abs(push[i, 0]) + abs(push[i, 1]) <= 0.0:
                continue
            sx, sy = target[i, 0] + push[i, 0] - pos[i, 0], target[i, 1] + push[i, 1] - pos[i, 1]
            scale = min(1.0, speed[i] * dt / max(np.hypot(sx, sy), 1e-12))
            x, y = pos[i, 0] + sx * scale, pos[i, 1] + sy * scale
            target[i, 0], target[i, 1], tick = _move(pos[i, 0], pos[i, 1], x, y, speed[i] * dt, stamp, tick, mesh)
    new_vel = (target - pos) / dt
    return target, new_vel


@numba.njit(cache=True, nogil=True)
def progress(pos, goal, cur, rest, best, last_progress, moving, t, arrive, step, stall_s):  # pragma: no cover
    """Walkers' progress this frame: ``(indices of those arrived at their stop, indices of those stalled)``.

    A walker within ``arrive`` m of its stop has arrived there. Any other walker whose remaining path
    (to its current corner, then along the corners ``rest``) is ``step`` m shorter than its best so far
    makes progress (``best`` and ``last_progress`` are updated in place, to ``t``); one that has made
    none for more than ``stall_s`` is stalled.
    """
    n = len(pos)
    done, stalled = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    n_done = n_stalled = 0
    for i in range(n):
        if not moving[i]:
            continue
        if np.hypot(goal[i, 0] - pos[i, 0], goal[i, 1] - pos[i, 1]) < arrive:
            done[n_done] = i
            n_done += 1
            continue
        remaining = np.hypot(cur[i, 0] - pos[i, 0], cur[i, 1] - pos[i, 1]) + rest[i]
        if remaining < best[i] - step:
            best[i], last_progress[i] = remaining, t
        elif t - last_progress[i] > stall_s:
            stalled[n_stalled] = i
            n_stalled += 1
    return done[:n_done], stalled[:n_stalled]


@numba.njit(cache=True, nogil=True)
def record_frame(pos, vel, smooth, heading, face, max_turn, xy, yaw, speed, frame):  # pragma: no cover
    """Store a frame: positions, headings, speeds into ``xy`` (N, F, 2), ``yaw`` and ``speed`` (N, F) at ``frame``.

    Headings (``heading``, updated in place) follow the velocities smoothed in place in ``smooth`` (an
    EMA of ``HEADING_SMOOTHING``) and are held while that is slower than ``STAND_SPEED``; someone with a
    point to face (``face`` (N, 2), nan for none) turns toward it by at most ``max_turn`` rad instead.
    """
    for i in range(len(vel)):
        smooth[i, 0] = (1 - HEADING_SMOOTHING) * smooth[i, 0] + HEADING_SMOOTHING * vel[i, 0]
        smooth[i, 1] = (1 - HEADING_SMOOTHING) * smooth[i, 1] + HEADING_SMOOTHING * vel[i, 1]
        if not np.isnan(face[i, 0]):
            want = np.arctan2(face[i, 1] - pos[i, 1], face[i, 0] - pos[i, 0])
            delta = (want - heading[i] + np.pi) % (2 * np.pi) - np.pi
            heading[i] = (heading[i] + min(max(delta, -max_turn), max_turn) + np.pi) % (2 * np.pi) - np.pi
        elif np.hypot(smooth[i, 0], smooth[i, 1]) > STAND_SPEED:
            heading[i] = np.arctan2(smooth[i, 1], smooth[i, 0])
        xy[i, frame, 0], xy[i, frame, 1] = pos[i, 0], pos[i, 1]
        yaw[i, frame], speed[i, frame] = heading[i], np.hypot(vel[i, 0], vel[i, 1])


@numba.njit(cache=True, nogil=True)
def avoidance_inputs(
    pos, vel, cur, nxt, has_next, goal, speed, moving, radius, dt, reach, frame, last_progress
):  # pragma: no cover
    """Who the avoidance model steers this frame, and its inputs for them.

    The walkers and whoever stands within ``reach`` of one (others cannot change the answer).
    Returns ``(rows (M,), positions (M, 2), velocities (M, 2), preferred velocities (M, 2)``
    (:func:`preferred_velocities`), ``body radii (M,)`` (of ``radius`` (N,)), ``speed limits (M,)`` (0 for those standing),
    ``held up (M,))``: seconds since each walker last made progress along its path (0 for those standing).
    """
    near = near_walkers(pos, moving, reach)
    pref = preferred_velocities(pos, cur, nxt, has_next, goal, speed, moving, radius, dt)
    rows = np.nonzero(moving | near)[0]
    limits = np.where(moving, speed, 0.0)[rows]
    held = np.where(moving, np.maximum(frame * dt - last_progress, 0.0), 0.0)[rows]
    return rows, pos[rows], vel[rows], pref[rows], radius[rows], limits, held


@numba.njit(cache=True, nogil=True)
def hold_starts(
    pos, vel, depart, dwell_until, last_progress, waited, moving, frame, fps, lookahead, comfort, max_wait
):  # pragma: no cover
    """Pedestrians due to walk off in ``frame`` who wait for a walker passing close (``_wait_for_passers``).

    Due: walking at ``frame`` but not at the frame before (a departure or the end of a dwell), and not yet
    waited ``max_wait`` s for this start. One waits while a walker (not due itself), moving on at its
    velocity, would come within ``comfort`` of it in the next ``lookahead`` s: its start moves to the next
    frame and it is taken out of ``moving``. All arrays are updated in place.
    """
    before, start = (frame - 1) / fps, (frame + 1) / fps
    n = len(pos)
    due = np.zeros(n, dtype=np.bool_)
    for k in range(n):
        due[k] = moving[k] and (depart[k] > before or dwell_until[k] > before) and waited[k] < max_wait
    for k in range(n):
        if not due[k]:
            continue
        held = False
        for j in range(n):
            if j == k or due[j] or not moving[j]:
                continue
            rx, ry = pos[j, 0] - pos[k, 0], pos[j, 1] - pos[k, 1]
            ax, ay = vel[j, 0] * lookahead, vel[j, 1] * lookahead
            s = min(max(-(rx * ax + ry * ay) / max(ax * ax + ay * ay, 1e-12), 0.0), 1.0)
            if np.hypot(rx + s * ax, ry + s * ay) < comfort:
                held = True
                break
        if held:
            if depart[k] > before:
                depart[k] = start
            else:
                dwell_until[k] = start
            last_progress[k] = max(last_progress[k], start)
            waited[k] += 1.0 / fps
            moving[k] = False


@numba.njit(cache=True, nogil=True)
def walking(depart, arrived, yield_until, dwell_until, t):  # pragma: no cover
    """(N,) bool: departed, not finished, not standing aside, not dwelling at a stop at time ``t``."""
    n = len(depart)
    out = np.empty(n, dtype=np.bool_)
    for i in range(n):
        out[i] = depart[i] <= t and not arrived[i] and yield_until[i] <= t and dwell_until[i] <= t
    return out


@numba.njit(cache=True, nogil=True)
def reached_corners(pos, cur, has_next, moving, reach):  # pragma: no cover
    """Indices of the walkers closer than ``reach`` to a corner that is not their goal."""
    out = np.empty(len(pos), dtype=np.int64)
    m = 0
    for i in range(len(pos)):
        if moving[i] and has_next[i] and np.hypot(cur[i, 0] - pos[i, 0], cur[i, 1] - pos[i, 1]) < reach:
            out[m] = i
            m += 1
    return out[:m]
