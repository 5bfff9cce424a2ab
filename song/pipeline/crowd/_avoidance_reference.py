"""Reference twins of the compiled personal-space anticipation and radii (used by tests only)."""

from __future__ import annotations

import numpy as np

from song.pipeline.crowd.avoidance import ANTICIPATION_GAIN, ANTICIPATION_MARGIN_M, PERSONAL_MARGIN_M


def anticipate_reference(
    positions: np.ndarray,
    velocities: np.ndarray,
    preferred: np.ndarray,
    comfort_distance: float,
    horizon: float,
    reach: float,
    room: np.ndarray | None = None,
) -> np.ndarray:
    """Reference twin of :func:`song.pipeline.crowd.avoidance.anticipate` (vectorised numpy, same arithmetic)."""
    speed = np.hypot(preferred[:, 0], preferred[:, 1])
    walking = np.flatnonzero(speed > 1e-6)
    if len(positions) < 2 or not len(walking):
        return preferred
    rel_p = positions[None, :, :] - positions[walking, None, :]  # (W, N, 2) walker → other
    rel_v = velocities[None, :, :] - preferred[walking, None, :]
    vv = (rel_v * rel_v).sum(-1)
    t = np.minimum(np.maximum(-(rel_p * rel_v).sum(-1) / np.where(vv > 1e-9, vv, 1.0), 0.0), horizon)
    miss = rel_p + rel_v * t[..., None]
    d = np.hypot(miss[..., 0], miss[..., 1])
    d[np.arange(len(walking)), walking] = np.inf
    d[np.hypot(rel_p[..., 0], rel_p[..., 1]) >= reach] = np.inf  # beyond reach: not considered
    heading = preferred[walking] / speed[walking, None]
    side = np.column_stack([-heading[:, 1], heading[:, 0]])
    lateral = (miss * side[:, None, :]).sum(-1)  # which side the other passes on
    away = np.where(lateral < -1e-6, 1.0, -1.0)  # go to the other side (a tie: to the right, as people do)
    aim = comfort_distance + ANTICIPATION_MARGIN_M
    weight = np.maximum(aim - d, 0.0) / aim / (1.0 + t)
    push = (away * weight).sum(axis=1)
    gain = ANTICIPATION_GAIN * (np.ones(len(positions)) if room is None else np.asarray(room, np.float64))
    bent = heading + gain[walking, None] * push[:, None] * side
    out = preferred.copy()
    out[walking] = bent / np.maximum(np.hypot(bent[:, 0], bent[:, 1]), 1e-9)[:, None] * speed[walking, None]
    return out


def personal_radii_reference(
    positions: np.ndarray,
    radii: np.ndarray,
    walking: np.ndarray,
    half_width: np.ndarray,
    comfort_radius: np.ndarray | float,
) -> np.ndarray:
    """Reference twin of :func:`song.pipeline.crowd.avoidance.personal_radii` (vectorised numpy)."""
    out = radii.astype(np.float64).copy()
    if not walking.any():
        return out
    comfort = np.broadcast_to(np.asarray(comfort_radius, dtype=np.float64), radii.shape)
    d = np.hypot(*(positions[:, None] - positions[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    fit = np.where(walking[None, :], 0.5 * d, d - radii[None, :] - comfort[:, None]).min(axis=1)
    personal = np.minimum(np.minimum(comfort, half_width - radii), fit - PERSONAL_MARGIN_M)
    return np.where(walking, np.maximum(personal, radii), radii)
