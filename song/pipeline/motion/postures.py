"""Postures at the objects pedestrians stand at: hands resting on a counter, desk or table.

The crowd turns a pedestrian standing at an object to face it (docs/crowd.md); here the motion stage
finds the frames where it stands at a surface it can rest its hands on -- an object whose label or
category names a counter, desk or table and whose top is at hand height -- and gives the gait, per
frame, the horizontal distance from the body to the surface's edge and the surface's height
(:attr:`song.pipeline.motion.types.Trajectory.surface`). The gait moves each hand up from where it
hangs to above the top short of the edge, then forward onto the surface (and back the same way), with
a planar two-bone solve of the arm in the sagittal plane at every frame (:func:`arm_to`).

Where people at a service counter or a standing desk put their hands is not tabulated in the gait
literature; the posture (hands a forearm's length ahead, arms slightly bent, the trunk leaning a few
degrees) is the neutral "standing work at a bench" posture of ergonomics texts, with the surface at
0.7-1.2 m (standing work heights; Grandjean, *Fitting the Task to the Man*, 1988).
"""

from __future__ import annotations

import numpy as np

from song.geometry.outline import nearest_on_outline

SURFACE_KEYWORDS = ("counter", "reception", "checkout", "desk", "help", "bar", "pharmacy", "workstation", "table")
SURFACE_HEIGHT_M = (0.7, 1.2)  # tops between these heights take resting hands
STAY_NEAR_M = 0.3  # within this of a leg's goal (0.5 m of the start: its jitter) a standing pedestrian is there
STAND_MPS = 0.01  # slower than this counts as standing
SETTLE_S = 1.5  # the hands go down after this long at the spot (the turn to face the object comes first)
LEAVE_S = 0.5  # and are off the surface this long before the pedestrian walks on
MIN_REST_S = 2.0  # a shorter rest is left alone: the hands take about a second to go on and one to come off
ONTO_SURFACE_M = 0.05  # the hands rest this far beyond the edge
PALM_M = 0.025  # the hand joint (mid-palm) lies this far above the surface
LIFT_CLEAR_M, EDGE_CLEAR_M = 0.06, 0.05  # on the way, the hand comes up this far above the top, short of the edge
SHOULDER_FLEX_DEG = (-30.0, 60.0)  # the upper arm from 30° behind the body to 60° raised forward


def is_surface(obj) -> bool:
    """The object is a counter, desk or table at standing-work height (``label``, ``category``, ``z_max``)."""
    text = f"{obj.label} {obj.category}".lower()
    return any(k in text for k in SURFACE_KEYWORDS) and SURFACE_HEIGHT_M[0] <= obj.z_max <= SURFACE_HEIGHT_M[1]


def surface_track(xy: np.ndarray, speed: np.ndarray, fps: float, stops: list, objects: dict) -> np.ndarray | None:
    """``(T, 2)`` [distance to the surface's edge, surface height] while resting hands on one, else nan.

    Args:
        xy: ``(T, 2)`` planned positions, m.
        speed: ``(T,)`` planned speed, m/s.
        fps: frame rate, Hz.
        stops: ``[(object id, (x, y) spot, radius m)]`` where the pedestrian stands at objects.
        objects: scene objects by id (``label``, ``category``, ``footprint``, ``z_max``).

    Returns:
        None when the pedestrian never stands at a surface long enough.
    """
    out = np.full((len(xy), 2), np.nan)
    standing = speed < STAND_MPS
    settle, leave = int(round(SETTLE_S * fps)), int(round(LEAVE_S * fps))
    for oid, spot, radius in stops:
        obj = objects.get(oid)
        if obj is None or not is_surface(obj):
            continue
        at = standing & (np.hypot(*(xy - np.asarray(spot, dtype=np.float64)).T) < radius)
        # each maximal run of frames at the spot, trimmed at both ends
        edges = np.flatnonzero(np.diff(np.concatenate([[0], at.astype(np.int8), [0]])))
        for start, end in zip(edges[::2], edges[1::2], strict=True):
            lo, hi = start + settle, end - leave
            if hi - lo < MIN_REST_S * fps:
                continue
            outline = np.asarray(obj.footprint, dtype=np.float64)
            out[lo:hi, 0] = nearest_on_outline(outline, xy[lo:hi])[1]
            out[lo:hi, 1] = obj.z_max
    return out if np.isfinite(out[:, 0]).any() else None


def arm_to(
    forward_m: np.ndarray, height_m: np.ndarray, shoulder: np.ndarray, upper: float, fore: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shoulder flexion and elbow flexion (rad) putting the hand at a point, and where it is possible.

    A planar two-bone solve in the sagittal plane: the hand joint at ``forward_m`` ahead of the standing
    body and ``height_m`` above the floor, from a shoulder at ``shoulder`` = (forward, height) m. The
    elbow bends forward (flexion ≥ 0); points out of reach, or needing the shoulder flexed outside
    ``SHOULDER_FLEX_DEG``, are not possible (angles 0 there).

    Args:
        forward_m: ``(T,)`` m (nan: no point).
        height_m: ``(T,)`` m.
        shoulder: ``(2,)`` or ``(T, 2)``: the shoulder's forward offset and height in the body, m.
        upper: upper-arm length (shoulder to elbow), m.
        fore: forearm length (elbow to the hand joint), m.

    Returns:
        ``(shoulder flexion (T,), elbow flexion (T,), possible (T,) bool)``.
    """
    shoulder = np.asarray(shoulder, dtype=np.float64)
    forward = np.nan_to_num(forward_m - shoulder[..., 0], nan=1e3)
    drop = shoulder[..., 1] - np.nan_to_num(height_m, nan=0.0)
    reach = np.hypot(forward, drop)
    cos_inner = (upper**2 + fore**2 - reach**2) / (2 * upper * fore)
    elbow = np.pi - np.arccos(np.clip(cos_inner, -1.0, 1.0))
    shoulder_flex = np.arctan2(forward, drop) - np.arctan2(fore * np.sin(elbow), upper + fore * np.cos(elbow))
    lo, hi = np.radians(SHOULDER_FLEX_DEG)
    possible = np.isfinite(forward_m) & (reach < 0.98 * (upper + fore)) & (shoulder_flex >= lo) & (shoulder_flex <= hi)
    return np.where(possible, shoulder_flex, 0.0), np.where(possible, elbow, 0.0), possible


def arm_on_surface(
    edge_m: np.ndarray, height_m: np.ndarray, shoulder: np.ndarray, upper: float, fore: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`arm_to` the resting hand: ``ONTO_SURFACE_M`` beyond the edge, ``PALM_M`` above the top.

    Args:
        edge_m: ``(T,)`` horizontal distance from the body to the surface's edge, m (nan: no surface).
        height_m: ``(T,)`` surface height, m.
        shoulder: as for :func:`arm_to`.
        upper: as for :func:`arm_to`.
        fore: as for :func:`arm_to`.
    """
    return arm_to(edge_m + ONTO_SURFACE_M, height_m + PALM_M, shoulder, upper, fore)
