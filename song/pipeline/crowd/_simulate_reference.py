"""Reference twins of the compiled crowd pair loops (used by tests only)."""

from __future__ import annotations

import numpy as np


def near_walkers_reference(pos: np.ndarray, moving: np.ndarray, reach: float) -> np.ndarray:
    """Reference twin of :func:`song.pipeline.crowd._crowd_kernel.near_walkers` (all-pairs numpy)."""
    walkers = np.flatnonzero(moving)
    d = np.hypot(*(pos[:, None] - pos[None, walkers]).transpose(2, 0, 1))
    d[walkers, np.arange(len(walkers))] = np.inf
    return (d < reach).any(axis=1)


def overlap_push_reference(
    target: np.ndarray, moving: np.ndarray, radius: np.ndarray, margin: float
) -> tuple[np.ndarray, bool]:
    """Reference twin of :func:`song.pipeline.crowd._crowd_kernel.overlap_push` (all-pairs numpy)."""
    diff = target[:, None, :] - target[None, :, :]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    np.fill_diagonal(dist, np.inf)
    overlap = np.clip(radius[:, None] + radius[None, :] + margin - dist, 0.0, None)
    share = np.where(moving[None, :], 0.5, 1.0)
    push = (diff / np.maximum(dist, 1e-9)[..., None] * (share * overlap)[..., None]).sum(axis=1)
    push[~moving] = 0.0
    return push, bool(overlap[moving].any())  # overlaps between people standing do not count


def preferred_velocities_reference(pos, cur, nxt, has_next, goal, speed, moving, radius, dt) -> np.ndarray:
    """Reference twin of :func:`song.pipeline.crowd._crowd_kernel.preferred_velocities` (vectorised numpy)."""
    pref = np.zeros_like(pos)
    idx = np.flatnonzero(moving)
    if not len(idx):
        return pref
    c0, c1, nxt_ok, p = cur[idx], nxt[idx], has_next[idx], pos[idx]
    dir0 = c0 - p
    len0 = np.hypot(dir0[:, 0], dir0[:, 1])
    dir1 = c1 - p
    dir1 /= np.maximum(np.hypot(dir1[:, 0], dir1[:, 1]), 1e-3)[:, None]
    steer = np.where(nxt_ok[:, None], dir0 - dir1 * (0.5 * len0)[:, None], dir0)
    d_goal = np.hypot(*(goal[idx] - p).T)
    desired = speed[idx] * np.minimum(1.0, d_goal / (2.0 * radius[idx]))
    desired = np.where(nxt_ok, desired, np.minimum(desired, len0 / dt))
    pref[idx] = steer / np.maximum(np.hypot(steer[:, 0], steer[:, 1]), 1e-9)[:, None] * desired[:, None]
    return pref


def accelerate_reference(vel: np.ndarray, wanted: np.ndarray, limit: float, turn_limit: float = -1.0) -> np.ndarray:
    """Reference twin of :func:`song.pipeline.crowd._crowd_kernel.accelerate` (with complex numbers)."""
    v, w = complex(*vel), complex(*wanted)
    sideways = limit if turn_limit < 0 else turn_limit
    if abs(v) > limit and abs(w) > limit and abs(np.angle(w / v)) <= np.pi / 2:
        turn = np.clip(np.angle(w / v), -sideways / abs(v), sideways / abs(v))
        new = v / abs(v) * np.exp(1j * turn) * np.clip(abs(w), abs(v) - limit, abs(v) + limit)
    else:
        new = v + (w - v) * min(1.0, limit / max(abs(w - v), 1e-300))
    return np.array([new.real, new.imag])


def _move_reference(mesh, pos: np.ndarray, target: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Reference twin of :func:`song.pipeline.crowd._crowd_kernel._move` for many steps (numpy and navmesh calls)."""
    target = mesh.constrain_moves(pos, target)
    disp = target - pos
    size = np.hypot(disp[:, 0], disp[:, 1])
    over = np.flatnonzero(size > limit * (1 + 1e-9))
    if len(over):
        scaled = pos[over] + disp[over] * (limit[over] / size[over])[:, None]
        ok = mesh.segment_clear(pos[over], scaled) & mesh.contains(scaled, tol=1e-9)
        target[over] = np.where(ok[:, None], scaled, pos[over])
    return target


def settle_moves_reference(
    mesh, pos, vel, rows, wanted, moving, speed, dt, accel_limit, radius, margin, passes, turn_limit=-1.0
):
    """Reference twin of :func:`song.pipeline.crowd._crowd_kernel.settle_moves` (numpy and navmesh calls).

    ``mesh`` is the :class:`song.geometry.navmesh.Navmesh` itself.
    """
    full = np.zeros_like(vel)
    full[rows] = wanted
    new_vel = np.array([accelerate_reference(v, f, accel_limit, turn_limit) for v, f in zip(vel, full, strict=True)])
    new_vel = new_vel.reshape(-1, 2)
    new_vel[~moving] = 0.0
    target = pos.copy()
    max_step = speed * dt
    rows = np.flatnonzero(moving)
    if len(rows):
        target[rows] = _move_reference(mesh, pos[rows], pos[rows] + new_vel[rows] * dt, max_step[rows])
    for _ in range(passes):
        push, found = overlap_push_reference(target, moving, radius, margin)
        if not found:
            break
        step = target + push - pos
        step *= np.minimum(1.0, max_step[:, None] / np.maximum(np.hypot(step[:, 0], step[:, 1]), 1e-12)[:, None])
        rows = np.flatnonzero(moving & (np.abs(push).sum(axis=1) > 0))
        if len(rows):
            target[rows] = _move_reference(mesh, pos[rows], pos[rows] + step[rows], max_step[rows])
    return target, (target - pos) / dt
