"""Postures at the objects pedestrians stand at: hands resting on a counter, desk or table; browsing a shelf.

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

At a shelf taller than that (:func:`is_shelf`) the pedestrian browses instead
(:attr:`song.pipeline.motion.types.Trajectory.shelf`, :func:`browse_plan`): it looks along the shelf
point after point and now and then touches an item at arm's height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from song.geometry.outline import nearest_on_outline
from song.pipeline.motion.types import held_rows, min_jerk, true_runs

SURFACE_KEYWORDS = ("counter", "reception", "checkout", "desk", "help", "bar", "pharmacy", "workstation", "table")
SURFACE_HEIGHT_M = (0.7, 1.2)  # tops between these heights take resting hands
STAY_NEAR_M = 0.3  # within this of a leg's goal (0.5 m of the start: its jitter) a standing pedestrian is there
STAND_MPS = 0.01  # slower than this counts as standing
SETTLE_S = 1.5  # the hands go down after this long at the spot (the turn to face the object comes first)
LEAVE_S = 0.5  # and are off the surface this long before the pedestrian walks on
MIN_REST_S = 2.0  # a shorter rest is left alone: the hands take about a second to go on and one to come off
ONTO_SURFACE_M = 0.05  # the hands rest this far beyond the edge
PALM_M = 0.025  # the hand joint (mid-palm) lies this far above the surface
LIFT_CLEAR_M, EDGE_CLEAR_M = 0.03, 0.05  # on the way, the hand (even pointing down) clears the top, short of the edge
SHOULDER_FLEX_DEG = (-30.0, 90.0)  # the upper arm from 30° behind the trunk to 90° raised forward of it
REACH_FLEX_DEG = (-30.0, 110.0)  # reaching for an item, up to 110° forward (shoulder flexion reaches ~170°)
# Browsing a shelf (a stay at an object ``is_shelf`` takes): the pedestrian looks along it, point after
# point, and now and then touches an item at arm's height. Visual search of a shelf goes by fixations of
# a fraction of a second to a few seconds with head movements between them; the figures below are our
# choice for a calm browse, not measured values.
SHELF_KEYWORDS = ("shelf", "shelving", "bookcase", "book", "rack", "display")
SHELF_MIN_TOP_M = SURFACE_HEIGHT_M[1]  # a shelf one browses standing reaches above this (no surface does)
LOOK_S = (1.5, 3.0)  # each look lasts this long (uniform)
GAZE_MOVE_S = 0.4  # the gaze moves from one point to the next over this long
LOOK_SPAN_M = 0.6  # points looked at lie this far left or right of straight ahead along the shelf
LOOK_HEIGHT_M = (0.5, 1.8)  # and between these heights (capped at the shelf's top)
REACH_SHARE = 0.8  # of the looks at a point the hand can touch, this share ends in a touch
REACH_HEIGHT_M = (0.9, 1.6)  # a hand touches items between these heights
REACH_SIDE_M = 0.35  # and no farther left or right than this (the hand on that side goes)
REACH_S = (0.8, 0.6, 0.8)  # out, resting on the item, back (peak hand speed ~2 m/s)
INTO_SHELF_M = 0.03  # the touching mid-palm lies this far past the shelf's front
BROWSE_RAMP_S = 0.5  # browsing fades in and out over about this long


def is_surface(obj) -> bool:
    """The object is a counter, desk or table at standing-work height (``label``, ``category``, ``z_max``)."""
    text = f"{obj.label} {obj.category}".lower()
    return any(k in text for k in SURFACE_KEYWORDS) and SURFACE_HEIGHT_M[0] <= obj.z_max <= SURFACE_HEIGHT_M[1]


def is_shelf(obj) -> bool:
    """The object is a shelf, bookcase, rack or display one browses standing (top above ``SHELF_MIN_TOP_M``)."""
    text = f"{obj.label} {obj.category}".lower()
    return any(k in text for k in SHELF_KEYWORDS) and obj.z_max > SHELF_MIN_TOP_M


def stay_track(xy: np.ndarray, speed: np.ndarray, fps: float, stops: list, objects: dict, accept) -> np.ndarray | None:
    """``(T, 2)`` [distance to the object's outline, its top height] while standing at one ``accept`` takes, else nan.

    Each maximal run of standing frames at a stop is trimmed by ``SETTLE_S`` after arriving and
    ``LEAVE_S`` before leaving; what is left of it counts when it lasts at least ``MIN_REST_S``.

    Args:
        xy: ``(T, 2)`` planned positions, m.
        speed: ``(T,)`` planned speed, m/s.
        fps: frame rate, Hz.
        stops: ``[(object id, (x, y) spot, radius m)]`` where the pedestrian stands at objects.
        objects: scene objects by id (``label``, ``category``, ``footprint``, ``z_max``).
        accept: which objects count (:func:`is_surface`, :func:`is_shelf`).

    Returns:
        None when the pedestrian never stands at such an object long enough.
    """
    out = np.full((len(xy), 2), np.nan)
    standing = speed < STAND_MPS
    settle, leave = int(round(SETTLE_S * fps)), int(round(LEAVE_S * fps))
    for oid, spot, radius in stops:
        obj = objects.get(oid)
        if obj is None or not accept(obj):
            continue
        at = standing & (np.hypot(*(xy - np.asarray(spot, dtype=np.float64)).T) < radius)
        for start, end in true_runs(at):  # each maximal run of frames at the spot, trimmed at both ends
            lo, hi = start + settle, end - leave
            if hi - lo < MIN_REST_S * fps:
                continue
            outline = np.asarray(obj.footprint, dtype=np.float64)
            out[lo:hi, 0] = nearest_on_outline(outline, xy[lo:hi])[1]
            out[lo:hi, 1] = obj.z_max
    return out if np.isfinite(out[:, 0]).any() else None


def surface_track(xy: np.ndarray, speed: np.ndarray, fps: float, stops: list, objects: dict) -> np.ndarray | None:
    """:func:`stay_track` of the counters, desks and tables (:func:`is_surface`) the pedestrian rests its hands on."""
    return stay_track(xy, speed, fps, stops, objects, is_surface)


def shelf_track(xy: np.ndarray, speed: np.ndarray, fps: float, stops: list, objects: dict) -> np.ndarray | None:
    """:func:`stay_track` of the shelves (:func:`is_shelf`) the pedestrian browses."""
    return stay_track(xy, speed, fps, stops, objects, is_shelf)


@dataclass(frozen=True)
class Browse:
    """Where a pedestrian browsing a shelf looks and what it touches, per frame.

    Attributes:
        on: ``(T,)`` 0-1, how much the pedestrian browses (ramped on and off).
        look: ``(T, 2)`` [along the shelf m (left +), height m] of the point looked at on the shelf's front
            (between stays, the last one's).
        reach: ``(T,)`` 0-1, how far one hand has gone toward the point looked at.
        left: ``(T,)`` bool, the reaching hand is the left one.
    """

    on: np.ndarray
    look: np.ndarray
    reach: np.ndarray
    left: np.ndarray


def browse_plan(shelf: np.ndarray, fps: float, seed: int) -> Browse:
    """Looks along the shelf and touches of items on it, over every stay of ``shelf`` (a :func:`shelf_track`).

    Each stay is split into looks of ``LOOK_S`` seconds at points drawn along the shelf (``LOOK_SPAN_M``
    either side of straight ahead, at ``LOOK_HEIGHT_M`` capped at the top); the gaze moves from one
    to the next with a minimum-jerk profile over ``GAZE_MOVE_S``. A look at a point the hand can touch
    (``REACH_HEIGHT_M``, ``REACH_SIDE_M``) ends in a touch with ``REACH_SHARE`` probability (the look
    lasting as long as the touch needs, within the stay): once the gaze is there, the hand on that
    side goes out, rests and comes back over ``REACH_S``. Deterministic in ``seed``.
    """
    n = len(shelf)
    rng = np.random.default_rng(seed)
    look, reach, left = np.full((n, 2), np.nan), np.zeros(n), np.zeros(n, dtype=bool)
    move = int(round(GAZE_MOVE_S * fps))
    touch = np.concatenate([min_jerk(np.linspace(0.0, 1.0, int(round(s * fps)))) for s in REACH_S[:1]]
                           + [np.ones(int(round(REACH_S[1] * fps)))]
                           + [min_jerk(np.linspace(1.0, 0.0, int(round(REACH_S[2] * fps))))])  # fmt: skip
    for lo, hi in true_runs(np.isfinite(shelf[:, 0])):  # each stay
        f, previous = lo, None
        while f < hi:
            point = np.array([rng.uniform(-LOOK_SPAN_M, LOOK_SPAN_M),
                              rng.uniform(LOOK_HEIGHT_M[0], min(LOOK_HEIGHT_M[1], shelf[lo, 1]))])  # fmt: skip
            length = int(round(rng.uniform(*LOOK_S) * fps))
            reachable = REACH_HEIGHT_M[0] <= point[1] <= REACH_HEIGHT_M[1] and abs(point[0]) <= REACH_SIDE_M
            touching = rng.random() < REACH_SHARE and reachable
            if touching:  # the look lasts as long as the touch needs
                length = max(length, move + len(touch))
            end = min(f + length, hi)
            look[f:end] = point
            if previous is not None:  # the gaze travels from the last point
                w = min_jerk(np.arange(1, move + 1) / move)[: end - f, None]
                look[f : f + len(w)] = previous + w * (point - previous)
            if touching and f + move + len(touch) <= end:
                reach[f + move : f + move + len(touch)] = touch
                left[f + move : f + move + len(touch)] = point[0] >= 0.0
            f, previous = end, point
    on = gaussian_filter1d(np.isfinite(shelf[:, 0]).astype(np.float64), BROWSE_RAMP_S / 4.0 * fps, mode="nearest")
    return Browse(on=on, look=np.nan_to_num(held_rows(look)), reach=reach, left=left)  # held between stays


def arm_to(
    forward_m: np.ndarray, height_m: np.ndarray, shoulder: np.ndarray, upper: float, fore: float,
    flex_deg: tuple = SHOULDER_FLEX_DEG, trunk_pitch: float | np.ndarray = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Shoulder flexion and elbow flexion (rad) putting the hand at a point, and where it is possible.

    A planar two-bone solve in the sagittal plane: the hand joint at ``forward_m`` ahead of the standing
    body and ``height_m`` above the floor, from a shoulder at ``shoulder`` = (forward, height) m. The
    elbow bends forward (flexion ≥ 0); points out of reach, or needing the shoulder flexed outside
    ``flex_deg`` (from the vertical), are not possible (angles 0 there).

    Args:
        forward_m: ``(T,)`` m (nan: no point).
        height_m: ``(T,)`` m.
        shoulder: ``(2,)`` or ``(T, 2)``: the shoulder's forward offset and height in the body, m.
        upper: upper-arm length (shoulder to elbow), m.
        fore: forearm length (elbow to the hand joint), m.
        flex_deg: the shoulder's flexion range relative to the trunk, degrees.
        trunk_pitch: how far the trunk leans forward, rad (scalar or ``(T,)``): an arm hanging straight
            down is flexed this much relative to the trunk.

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
    lo, hi = np.radians(flex_deg[0]) - trunk_pitch, np.radians(flex_deg[1]) - trunk_pitch  # from the vertical
    possible = np.isfinite(forward_m) & (reach < 0.98 * (upper + fore)) & (shoulder_flex >= lo) & (shoulder_flex <= hi)
    return np.where(possible, shoulder_flex, 0.0), np.where(possible, elbow, 0.0), possible


def arm_on_surface(
    edge_m: np.ndarray, height_m: np.ndarray, shoulder: np.ndarray, upper: float, fore: float,
    trunk_pitch: float | np.ndarray = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """:func:`arm_to` the resting hand: ``ONTO_SURFACE_M`` beyond the edge, ``PALM_M`` above the top.

    Args:
        edge_m: ``(T,)`` horizontal distance from the body to the surface's edge, m (nan: no surface).
        height_m: ``(T,)`` surface height, m.
        shoulder: as for :func:`arm_to`.
        upper: as for :func:`arm_to`.
        fore: as for :func:`arm_to`.
        trunk_pitch: as for :func:`arm_to`.
    """
    return arm_to(edge_m + ONTO_SURFACE_M, height_m + PALM_M, shoulder, upper, fore, trunk_pitch=trunk_pitch)
