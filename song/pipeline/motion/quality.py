"""Motion quality figures (the gait's normative targets), per pedestrian, written into ``meta.json``.

Definitions:

- **Foot-skating ratio** (GMD): a frame skates when, for either foot, the toe (ball-of-foot joint) is
  below 5 cm in this and the next frame and its horizontal speed exceeds 0.5 m/s both instantly and
  as a centred 5-frame mean; the ratio is skating frames over all frames.
- **Sole gap**: height of a foot joint above its rest height (ankle, ball of foot); the lowest of a
  foot's two is that foot's sole gap. *Penetration* is ``max(0, −min gap)`` over both feet;
  *floating* is a contact-frame sole gap above zero.
- **Root error**: horizontal distance between the pelvis and the planned trajectory.
- **Cadence**: steps/s measured from consecutive touchdowns of the same foot (``2 / period``),
  compared with the walk-ratio model at the planned mean speed over that stride; only strides where
  the plan walks steadily (speed > 0.3 m/s throughout) count.
- **Feet clash**: the two feet's centre lines (ankle → ball) closer than 4 cm in a frame: the soles
  overlap by more than half, one foot passes through the other (:func:`feet_gap`).
- **Joint limits**: knee flexion is the angle of the knee's local rotation about the body's lateral
  axis (+y), positive when the shin folds backwards; elbow flexion is about −z (left) / +z (right),
  positive when the forearm folds forwards. Hyper-extension is a negative angle.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from song.geometry.rotations import quat_to_axis_angle, quat_to_matrix, vector_norm, yaw_of_matrix
from song.geometry.skeleton import JOINT_INDEX as J

TOES = (J["left_foot"], J["right_foot"])
ANKLES = (J["left_ankle"], J["right_ankle"])
SKATE_HEIGHT_M = 0.05
SKATE_SPEED_MPS = 0.5


def foot_skating_ratio(joints: np.ndarray, fps: float) -> float:
    """GMD foot-skating ratio of world joints ``(T, 24, 3)`` (see the module docstring)."""
    n = len(joints)
    if n < 2:
        return 0.0
    skating = np.zeros(n - 1, dtype=bool)
    for toe in TOES:
        p = joints[:, toe]
        low = (p[:-1, 2] < SKATE_HEIGHT_M) & (p[1:, 2] < SKATE_HEIGHT_M)
        speed = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1) * fps
        mean5 = uniform_filter1d(speed, 5, mode="nearest")
        skating |= low & (speed > SKATE_SPEED_MPS) & (mean5 > SKATE_SPEED_MPS)
    return float(skating.sum() / n)


def sole_gaps(joints: np.ndarray, rest_joints: np.ndarray) -> np.ndarray:
    """Per-foot sole gaps ``(T, 2)`` metres: min over (ankle, ball) of height above its rest height."""
    gaps = []
    for ankle, toe in zip(ANKLES, TOES, strict=True):
        gaps.append(np.minimum(joints[:, ankle, 2] - rest_joints[ankle, 2], joints[:, toe, 2] - rest_joints[toe, 2]))
    return np.stack(gaps, axis=-1)


FEET_CLASH_M = 0.04  # foot centre lines closer than this: the soles (~9 cm wide) overlap by more than half


def feet_gap(joints: np.ndarray, samples: int = 5) -> np.ndarray:
    """Per-frame distance ``(T,)`` m between the two feet's centre lines (ankle → ball of foot).

    Each segment is sampled at ``samples`` evenly spaced points; the gap is the smallest distance
    between a left and a right point (exact to ~1 cm at a foot length of 15 cm).
    """
    w = np.linspace(0.0, 1.0, samples)[None, :, None]
    feet = []
    for ankle, toe in zip(ANKLES, TOES, strict=True):
        feet.append(joints[:, None, ankle] + w * (joints[:, None, toe] - joints[:, None, ankle]))
    d = vector_norm(feet[0][:, :, None] - feet[1][:, None, :])
    return d.min(axis=(1, 2))


def knee_elbow_flexion(local_quats: np.ndarray) -> dict[str, np.ndarray]:
    """Flexion angles (radians, ``(T, 2)`` left/right) of knees and elbows from local rotations."""
    aa = quat_to_axis_angle(local_quats)
    knee = aa[:, [J["left_knee"], J["right_knee"]], 1]
    elbow = np.stack([-aa[:, J["left_elbow"], 2], aa[:, J["right_elbow"], 2]], axis=-1)
    return {"knee": knee, "elbow": elbow}


def cadence_errors(
    contacts: np.ndarray, t: np.ndarray, plan_speed: np.ndarray, walk_ratio: float, min_cadence_spm: float
) -> np.ndarray:
    """Relative cadence errors ``(S,)`` of the steady strides (see the module docstring)."""
    errors = []
    for foot in range(contacts.shape[1]):
        c = contacts[:, foot]
        onsets = np.flatnonzero(c[1:] & ~c[:-1]) + 1
        for a, b in zip(onsets[:-1], onsets[1:], strict=True):
            v = plan_speed[a : b + 1]
            if len(v) == 0 or v.min() < 0.3:
                continue
            measured = 2.0 / (t[b] - t[a])
            model = max(np.sqrt(v.mean() / walk_ratio), min_cadence_spm / 60.0)
            errors.append(measured / model - 1.0)
    return np.asarray(errors, dtype=np.float64)


def motion_quality(
    joints: np.ndarray,
    local_quats: np.ndarray,
    rest_joints: np.ndarray,
    contacts: np.ndarray,
    t: np.ndarray,
    plan_xy: np.ndarray,
    plan_speed: np.ndarray,
    walk_ratio: float,
    min_cadence_spm: float,
) -> dict[str, Any]:
    """All quality figures of one motion as a JSON-ready dict (metres, degrees, ratios).

    Args:
        joints: ``(T, 24, 3)`` world joints, m.
        local_quats: ``(T, 24, 4)`` wxyz parent-local rotations.
        rest_joints: ``(24, 3)`` rest pose, m.
        contacts: ``(T, 2)`` bool foot contacts (left, right).
        t: ``(T,)`` s.
        plan_xy: ``(T, 2)`` planned root positions, m.
        plan_speed: ``(T,)`` planned speed, m/s.
        walk_ratio: the cadence model's walk ratio, m·s.
        min_cadence_spm: the cadence model's floor, steps/min.
    """
    fps = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 30.0
    gaps = sole_gaps(joints, rest_joints)
    lowest = gaps.min(axis=1)
    penetration = np.maximum(0.0, -lowest)
    contact_gaps = gaps[contacts]
    root_error = np.linalg.norm(joints[:, 0, :2] - plan_xy, axis=1)
    cadence = cadence_errors(contacts, t, plan_speed, walk_ratio, min_cadence_spm)
    flex = knee_elbow_flexion(local_quats)
    gap = feet_gap(joints)

    def r(x: float, digits: int = 5) -> float:
        return round(float(x), digits)

    return {
        "n_frames": int(len(t)),
        "foot_skating_ratio": r(foot_skating_ratio(joints, fps)),
        "penetration_p99_m": r(np.percentile(penetration, 99)),
        "penetration_max_m": r(penetration.max()),
        "contact_float_max_m": r(contact_gaps.max() if contact_gaps.size else 0.0),
        "contact_float_p99_m": r(np.percentile(contact_gaps, 99) if contact_gaps.size else 0.0),
        "root_error_mean_m": r(root_error.mean()),
        "root_error_max_m": r(root_error.max()),
        "contact_fraction": r(contacts.mean(), 4),
        "cadence_strides": int(cadence.size),
        "cadence_error_median": r(np.median(np.abs(cadence)) if cadence.size else 0.0, 4),
        "cadence_error_max": r(np.abs(cadence).max() if cadence.size else 0.0, 4),
        "feet_gap_min_m": r(gap.min(), 4),
        "feet_clash_frames": int((gap < FEET_CLASH_M).sum()),
        "knee_flexion_min_deg": r(np.degrees(flex["knee"].min()), 3),
        "knee_flexion_max_deg": r(np.degrees(flex["knee"].max()), 3),
        "elbow_flexion_min_deg": r(np.degrees(flex["elbow"].min()), 3),
        "elbow_flexion_max_deg": r(np.degrees(flex["elbow"].max()), 3),
    }


# Normative ranges the procedural gait is held to, healthy adults walking at 1.0-1.4 m/s:
# knee flexion ~0-5° at heel strike, a 10-25° loading-response wave, 55-68° peak in swing, hip sagittal
# range 35-50° (Perry & Burnfield, Gait Analysis, 2nd ed. 2010, ch. 7-8; Winter, Biomechanics and Motor
# Control of Human Gait, 1991); walk ratio 0.34-0.44 m·s across 0.5-1.6 m/s (Sekiya & Nagasaki 1998,
# Gait Posture 7:225); cadence 100-120 steps/min at 1.3 m/s (Grieve & Gear 1966; Oberg et al. 1993);
# transverse pelvic rotation ±3-6° (Perry & Burnfield 2010, ch. 9; Bruijn et al. 2008, Gait Posture 28:93);
# shoulder (upper-arm) sagittal swing ±10-25°, opposite to the hip of the same side (Murray et al. 1967,
# J. Bone Joint Surg. 49A:336; Collins et al. 2009, Proc. R. Soc. B 276:3679).
NORMATIVE = {
    "knee_heel_strike_deg": (0.0, 8.0),
    "knee_loading_peak_deg": (10.0, 25.0),
    "knee_swing_peak_deg": (55.0, 68.0),
    "hip_range_deg": (35.0, 50.0),
    "walk_ratio_m_s": (0.34, 0.44),
    "pelvic_rotation_deg": (3.0, 6.0),
    "shoulder_swing_deg": (10.0, 25.0),
}
CADENCE_AT_1_3_SPM = (100.0, 120.0)
LOADING_WINDOW = 0.15  # loading response: the first 15 % of the gait cycle after heel strike
STEADY_MPS = 0.3  # strides whose planned speed stays above this count


def _pelvis_yaw(local_quats: np.ndarray) -> np.ndarray:
    """Unwrapped yaw (degrees) of the pelvis's forward axis (the root's local rotation is global)."""
    return np.degrees(np.unwrap(yaw_of_matrix(quat_to_matrix(local_quats[:, 0]))))


def upper_arm_swing(joints: np.ndarray, local_quats: np.ndarray, side: str) -> np.ndarray:
    """Sagittal angle (degrees, ``(T,)``) of one upper arm, positive forward of the trunk's vertical.

    The shoulder→elbow direction projected on the pelvis's forward axis and the vertical.
    """
    d = joints[:, J[f"{side}_elbow"]] - joints[:, J[f"{side}_shoulder"]]
    yaw = np.radians(_pelvis_yaw(local_quats))
    forward = d[:, 0] * np.cos(yaw) + d[:, 1] * np.sin(yaw)
    return np.degrees(np.arctan2(forward, -d[:, 2]))


def _detrended_half_range(x: np.ndarray) -> float:
    """Half the peak-to-peak range of ``x`` after removing its straight line (a turn's drift)."""
    trend = np.linspace(x[0], x[-1], len(x))
    y = x - trend
    return 0.5 * float(y.max() - y.min())


def gait_cycle_figures(
    local_quats: np.ndarray, contacts: np.ndarray, t: np.ndarray, speed: np.ndarray, joints: np.ndarray | None = None
) -> dict:
    """Joint figures per steady stride, as medians over the strides (degrees, m·s, steps/min).

    A stride runs from one touchdown (contact onset) of a foot to its next; knee flexion is the
    knee's local rotation about +y, hip flexion minus the hip's (the thigh swinging forward); pelvic
    rotation is half the range of the pelvis's yaw over the stride (its drift removed). With world
    ``joints`` also the shoulder swing (half the range of the same side's :func:`upper_arm_swing`)
    and its correlation with that side's hip flexion (−1 is anti-phase). Returns ``{}`` when no
    stride is steady.
    """
    aa = np.degrees(quat_to_axis_angle(local_quats))
    pelvis_yaw = _pelvis_yaw(local_quats)
    arms = None if joints is None else [upper_arm_swing(joints, local_quats, side) for side in ("left", "right")]
    rows = []
    for foot, (hip, knee) in enumerate(((J["left_hip"], J["left_knee"]), (J["right_hip"], J["right_knee"]))):
        c = contacts[:, foot]
        onsets = np.flatnonzero(c[1:] & ~c[:-1]) + 1
        for a, b in zip(onsets[:-1], onsets[1:], strict=True):
            v = speed[a : b + 1]
            if v.min() < STEADY_MPS:
                continue
            flex = aa[a : b + 1, knee, 1]
            hip_flex = -aa[a : b + 1, hip, 1]
            load = flex[: max(2, int(round(LOADING_WINDOW * (b - a))) + 1)]
            cadence = 2.0 / (t[b] - t[a])  # steps/s
            row = {
                "speed_mps": float(v.mean()),
                "knee_heel_strike_deg": float(flex[0]),
                "knee_loading_peak_deg": float(load.max()),
                "knee_swing_peak_deg": float(flex.max()),
                "hip_range_deg": float(hip_flex.max() - hip_flex.min()),
                "pelvic_rotation_deg": _detrended_half_range(pelvis_yaw[a : b + 1]),
                "walk_ratio_m_s": float(v.mean() / cadence**2),
                "cadence_spm": float(60.0 * cadence),
            }
            if arms is not None:
                arm = arms[foot][a : b + 1]
                row["shoulder_swing_deg"] = _detrended_half_range(arm)
                row["arm_hip_correlation"] = float(np.corrcoef(arm, hip_flex)[0, 1])
            rows.append(row)
    if not rows:
        return {}
    return {key: round(float(np.median([r[key] for r in rows])), 4) for key in rows[0]} | {"strides": len(rows)}


HEADING_SEGMENTS = ("head", "spine3", "pelvis")
LEAD_WINDOW_S = 1.0  # leads are searched within ±1 s
LEAD_MIN_SPEED = 0.3  # only walking frames count


def heading_leads(
    local_quats: np.ndarray, rest_joints: np.ndarray, root_pos: np.ndarray, xy: np.ndarray, t: np.ndarray
) -> dict[str, float | None]:
    """How far ahead (s) the head, thorax and pelvis turn compared with the walked path.

    The lag that best aligns each segment's yaw rate with the path direction's yaw rate (the direction
    of the planned velocity) over the walking frames, by cross-correlation within ±``LEAD_WINDOW_S``;
    positive when the segment turns first. People turn the head ~0.2 s before the path in walking
    turns, trunk and pelvis a little later (Grasso et al. 1998, NeuroReport 9:1169; Patla et al. 1999,
    Exp. Brain Res. 129:629). None when the walk holds no turn to measure.
    """
    from song.geometry.fk import forward_kinematics

    fps = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 30.0
    vel = np.gradient(xy, t, axis=0) if len(t) > 2 else np.zeros_like(xy)
    speed = np.linalg.norm(vel, axis=1)
    path = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
    walking = speed > LEAD_MIN_SPEED
    path_rate = np.where(walking, np.gradient(path, t), 0.0) if len(t) > 2 else np.zeros(len(t))
    out: dict[str, float | None] = {name: None for name in HEADING_SEGMENTS}
    if np.abs(path_rate).max(initial=0.0) < 0.3:  # no turn faster than ~17°/s
        return out
    _, rots = forward_kinematics(rest_joints.astype(np.float64), local_quats.astype(np.float64), root_pos)
    window = int(round(LEAD_WINDOW_S * fps))
    for name in HEADING_SEGMENTS:
        seg = np.unwrap(np.arctan2(rots[:, J[name], 1, 0], rots[:, J[name], 0, 0]))
        rate = np.where(walking, np.gradient(seg, t), 0.0)
        best, lag = -np.inf, 0
        for k in range(-window, window + 1):  # segment at frame i aligns with the path at i + k
            a, b = (rate[: len(rate) - k], path_rate[k:]) if k >= 0 else (rate[-k:], path_rate[: len(rate) + k])
            score = float(a @ b)
            if score > best:
                best, lag = score, k
        out[name] = round(lag / fps, 3)
    return out
