"""Trajectory-consistency post-processing (paper appendix, "Kimodo motion generation details").

Applied to every generated motion, in the paper's order:

1. :func:`align_to_plan` — root heading and horizontal translation follow the planned trajectory
   (the low-frequency part of the error is removed; the gait's own sway and pelvic rotation stay);
2. :func:`resample_motion` — onto the trajectory's time stamps (linear root, slerp rotations);
3. :func:`smooth_motion` — Gaussian on the root, quaternion-aware smoothing of all rotations;
4. foot-ground correction — :func:`detect_contacts` (height + horizontal speed, per joint type:
   ankle and ball of the foot; where the generator gives its stance flags, as the procedural gait
   does, only within them, so a low shuffle step is not pinned to the floor), then :func:`lock_feet`:
   during a contact the foot is translated so its ball stays where it was planted and its sole
   touches the ground, blended in and out over a few frames; outside contacts the sole is kept above
   the ground (clearance). The pelvis is lowered where a corrected ankle would be out of reach, and
   the legs are re-solved with two-bone IK (hip–knee–ankle, pole = the current knee direction, never
   backwards of the pelvis and foot).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from scipy.ndimage import binary_closing, binary_opening, gaussian_filter1d, maximum_filter1d

from song.geometry.fk import forward_kinematics
from song.geometry.ik import two_bone_ik
from song.geometry.rotations import (
    matrix_to_quat,
    quat_about_z,
    quat_mul,
    quat_slerp,
    quat_to_matrix,
    vector_norm,
    yaw_of_matrix,
)
from song.geometry.skeleton import JOINT_INDEX as J
from song.pipeline.motion.types import Motion, Trajectory, body_heading, path_yaw, true_runs

LEGS = (
    (J["left_hip"], J["left_knee"], J["left_ankle"], J["left_foot"]),
    (J["right_hip"], J["right_knee"], J["right_ankle"], J["right_foot"]),
)
_REACH = 0.999  # fraction of the leg length an IK target may be from the hip
_MIN_CONTACT_FRAMES = 3  # shorter contact runs are noise
_MAX_CONTACT_GAP = 2  # shorter breaks inside a contact are noise


def _plan_at(traj: Trajectory, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xy = np.stack([np.interp(t, traj.t, traj.xy[:, k]) for k in (0, 1)], axis=-1)
    return xy, np.interp(t, traj.t, body_heading(path_yaw(traj), traj.t))


def align_to_plan(
    motion: Motion, traj: Trajectory, sigma_s: float = 1.0, max_offset_m: float = 0.02
) -> tuple[Motion, dict[str, float]]:
    """Align root heading and horizontal position with the plan at the motion's own time stamps.

    Args:
        motion: generated motion (any time stamps inside or around the plan's).
        traj: the planned trajectory.
        sigma_s: Gaussian width (s) separating the drift to remove from the gait's own oscillation.
        max_offset_m: largest horizontal pelvis offset from the plan kept after alignment.

    Returns:
        The aligned motion and residual figures before/after (metres, degrees).
    """
    fps = 1.0 / np.median(np.diff(motion.t)) if motion.n_frames > 1 else 30.0
    sigma = sigma_s * fps
    plan_xy, plan_yaw = _plan_at(traj, motion.t)
    root_rot = quat_to_matrix(motion.local_quats[:, 0])
    gen_yaw = np.unwrap(yaw_of_matrix(root_rot))
    dyaw = np.unwrap(plan_yaw - gen_yaw)
    dyaw = dyaw - 2 * np.pi * np.round(np.median(dyaw) / (2 * np.pi))
    drift = gaussian_filter1d(dyaw, sigma, mode="nearest") if motion.n_frames > 1 else dyaw
    quats = motion.local_quats.copy()
    quats[:, 0] = quat_mul(quat_about_z(drift), quats[:, 0])
    residual = motion.root_pos[:, :2] - plan_xy
    keep = residual - (gaussian_filter1d(residual, sigma, axis=0, mode="nearest") if motion.n_frames > 1 else residual)
    norm = np.linalg.norm(keep, axis=1, keepdims=True)
    keep = keep * np.minimum(1.0, max_offset_m / np.maximum(norm, 1e-12))
    root = motion.root_pos.copy()
    root[:, :2] = plan_xy + keep
    heading_after = np.degrees(np.abs(dyaw - drift))
    figures = {
        "root_error_before_mean_m": float(np.linalg.norm(residual, axis=1).mean()),
        "root_error_before_max_m": float(np.linalg.norm(residual, axis=1).max()),
        "root_error_after_mean_m": float(np.linalg.norm(keep, axis=1).mean()),
        "root_error_after_max_m": float(np.linalg.norm(keep, axis=1).max()),
        "heading_error_before_mean_deg": float(np.degrees(np.abs(dyaw)).mean()),
        "heading_error_before_max_deg": float(np.degrees(np.abs(dyaw)).max()),
        "heading_error_after_mean_deg": float(heading_after.mean()),
        "heading_error_after_max_deg": float(heading_after.max()),
    }
    return replace(motion, local_quats=quats, root_pos=root), figures


def resample_motion(motion: Motion, t: np.ndarray, frame: np.ndarray) -> Motion:
    """The motion at new time stamps ``t (T',)``: linear root, slerped rotations, clamped at the ends."""
    if motion.n_frames == len(t) and np.allclose(motion.t, t, atol=1e-9):
        return replace(motion, t=np.asarray(t, dtype=np.float64), frame=np.asarray(frame, dtype=np.int32))
    src = motion.t
    pos = np.clip(np.interp(t, src, np.arange(len(src))), 0, len(src) - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, len(src) - 1)
    w = pos - lo
    root = motion.root_pos[lo] * (1 - w)[:, None] + motion.root_pos[hi] * w[:, None]
    quats = quat_slerp(motion.local_quats[lo], motion.local_quats[hi], np.broadcast_to(w[:, None], (len(t), 24)))
    contacts = None
    if motion.contacts is not None:
        contacts = np.where((w < 0.5)[:, None], motion.contacts[lo], motion.contacts[hi])
    return replace(
        motion,
        t=np.asarray(t, dtype=np.float64),
        frame=np.asarray(frame, dtype=np.int32),
        local_quats=quats,
        root_pos=root,
        contacts=contacts,
    )


def smooth_motion(motion: Motion, sigma_frames: float) -> Motion:
    """Gaussian smoothing of the root and (quaternion-aware) of every joint rotation."""
    from song.geometry.rotations import smooth_quats

    if sigma_frames <= 0 or motion.n_frames < 3:
        return motion
    root = gaussian_filter1d(motion.root_pos, sigma_frames, axis=0, mode="nearest")
    quats = smooth_quats(motion.local_quats, sigma_frames, axis=0)
    return replace(motion, root_pos=root, local_quats=quats)


def _sole_gap(joints: np.ndarray, rest: np.ndarray, ankle: int, toe: int) -> np.ndarray:
    return np.minimum(joints[:, ankle, 2] - rest[ankle, 2], joints[:, toe, 2] - rest[toe, 2])


def detect_contacts(
    joints: np.ndarray, rest_joints: np.ndarray, fps: float, height_m: float = 0.05, speed_mps: float = 0.2
) -> np.ndarray:
    """Foot contacts ``(T, 2)`` bool (left, right) from joint heights and horizontal speeds.

    A foot is in contact when its ankle or its ball is both within ``height_m`` of its rest height
    and slower than ``speed_mps`` (3-D speed, so a lifting foot is not in contact); runs shorter than 3 frames are dropped and breaks of up to 2
    frames filled.
    """
    n = len(joints)
    out = np.zeros((n, 2), dtype=bool)
    for side, (_, _, ankle, toe) in enumerate(LEGS):
        flags = np.zeros(n, dtype=bool)
        for joint in (ankle, toe):
            height = joints[:, joint, 2] - rest_joints[joint, 2]
            if n > 1:
                speed = np.linalg.norm(np.gradient(joints[:, joint], axis=0), axis=1) * fps
            else:
                speed = np.zeros(1)
            flags |= (height < height_m) & (speed < speed_mps)
        if n > 2 * _MAX_CONTACT_GAP:
            padded = np.pad(flags, _MAX_CONTACT_GAP, mode="edge")
            flags = binary_closing(padded, np.ones(2 * _MAX_CONTACT_GAP + 1))[_MAX_CONTACT_GAP:-_MAX_CONTACT_GAP]
        if n > _MIN_CONTACT_FRAMES:
            padded = np.pad(flags, _MIN_CONTACT_FRAMES, mode="edge")
            opened = binary_opening(padded, np.ones(_MIN_CONTACT_FRAMES))
            flags = opened[_MIN_CONTACT_FRAMES:-_MIN_CONTACT_FRAMES]
        out[:, side] = flags
    return out


def foot_offsets(joints: np.ndarray, rest: np.ndarray, contacts: np.ndarray, blend_frames: int) -> np.ndarray:
    """Ankle translations ``(T, 2, 3)`` that lock planted feet, blend in/out and keep clearance.

    Each contact run only touches its own window (the run and ``blend_frames`` either side).
    """
    n = len(joints)
    offsets = np.zeros((n, 2, 3))
    frames = np.arange(n)
    for side, (_, _, ankle, toe) in enumerate(LEGS):
        gap = _sole_gap(joints, rest, ankle, toe)
        weight = np.zeros(n)
        for a, stop in true_runs(contacts[:, side]):
            b = stop - 1  # the run's last frame
            lo, hi = max(a - blend_frames, 0), min(b + blend_frames, n - 1) + 1
            f = frames[lo:hi]
            core = (f >= a) & (f <= b)
            lock = np.median(joints[a : b + 1, toe, :2], axis=0)
            delta = np.zeros((hi - lo, 3))
            delta[core, :2] = lock - joints[a : b + 1, toe, :2]
            delta[core, 2] = -gap[a : b + 1]
            w = core.astype(np.float64)
            if blend_frames > 0:
                before, after = f < a, f > b
                x = np.where(before, (f - (a - blend_frames - 1)) / (blend_frames + 1), 0.0)
                x = np.where(after, ((b + blend_frames + 1) - f) / (blend_frames + 1), x)
                ramp = x * x * (3 - 2 * x)
                w = np.where(before | after, ramp, w)
                delta[before] = delta[a - lo]
                delta[after] = delta[b - lo]
            take = w > weight[lo:hi]
            window = offsets[lo:hi, side]  # a view: assigning through it fills offsets
            window[take] = w[take, None] * delta[take]
            weight[lo:hi] = np.maximum(weight[lo:hi], w)
        # clearance: never below the ground
        offsets[:, side, 2] = np.maximum(offsets[:, side, 2], -gap)
    return offsets


def _lower_root(root: np.ndarray, hips: list[np.ndarray], targets: list[np.ndarray], leg: float) -> np.ndarray:
    """Pelvis heights lowered (smoothly, only where needed) so every ankle target is reachable."""
    deficit = np.zeros(len(root))
    reach = _REACH * leg
    for hip, target in zip(hips, targets, strict=True):
        horizontal = np.linalg.norm(target[:, :2] - hip[:, :2], axis=1)
        vertical = np.sqrt(np.maximum(reach * reach - horizontal * horizontal, (0.5 * reach) ** 2))
        deficit = np.maximum(deficit, hip[:, 2] - (target[:, 2] + vertical))
    if not np.any(deficit > 0):
        return root
    radius = 4
    if len(deficit) > 1:
        deficit = maximum_filter1d(deficit, 2 * radius + 1, mode="nearest")
        deficit = gaussian_filter1d(deficit, radius / 2.0, mode="nearest", truncate=2.0)
    out = root.copy()
    out[:, 2] -= deficit
    return out


def lock_feet(
    motion: Motion, contacts: np.ndarray, blend_frames: int = 4, fk: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[Motion, dict[str, float]]:
    """Foot locking + ground clearance with two-bone leg IK (see the module docstring).

    ``fk``: the motion's ``(joints, global rotations)`` when the caller has them already.
    """
    rest = motion.rest_joints
    joints, glob = fk if fk is not None else forward_kinematics(rest, motion.local_quats, motion.root_pos)
    offsets = foot_offsets(joints, rest, contacts, blend_frames)
    shift = vector_norm(offsets)
    moved = shift > 1e-7
    corrected = float((shift > 1e-3).any(axis=1).mean())
    if not moved.any():
        return replace(motion, contacts=contacts), {"feet_corrected_fraction": 0.0, "pelvis_lowered_max_m": 0.0}
    targets = [joints[:, ankle] + offsets[:, side] for side, (_, _, ankle, _) in enumerate(LEGS)]
    leg = float(
        np.linalg.norm(rest[J["left_knee"]] - rest[J["left_hip"]])
        + np.linalg.norm(rest[J["left_ankle"]] - rest[J["left_knee"]])
    )
    root = _lower_root(motion.root_pos, [joints[:, hip] for hip, _, _, _ in LEGS], targets, leg)
    if not np.array_equal(root, motion.root_pos):
        joints, glob = forward_kinematics(rest, motion.local_quats, root)
    quats = motion.local_quats.copy()
    for side, (hip, knee, ankle, _) in enumerate(LEGS):
        rows = moved[:, side] | (root[:, 2] != motion.root_pos[:, 2])
        if not rows.any():
            continue
        h, k, a = joints[rows, hip], joints[rows, knee], joints[rows, ankle]
        axis = a - h
        axis_unit = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        perp = (k - h) - np.sum((k - h) * axis_unit, axis=1, keepdims=True) * axis_unit
        # forward for a knee: between where the pelvis and the foot point (the generators' pole); the pelvis
        # alone turns ahead of the legs in a turn, and a knee checked against it alone was flipped backwards
        fwd = glob[rows, 0, :, 0] + glob[rows, ankle, :, 0]
        fwd = fwd / np.maximum(np.linalg.norm(fwd, axis=1, keepdims=True), 1e-12)
        size = np.linalg.norm(perp, axis=1, keepdims=True)
        blend = np.clip(size / 0.01, 0.0, 1.0) * (np.sum(perp * fwd, axis=1, keepdims=True) > 0)
        pole = perp / np.maximum(size, 1e-12) * blend + fwd * (1.0 - blend)
        _, _, d_root, d_mid = two_bone_ik(h, k, a, targets[side][rows], pole, pole)
        thigh = d_root @ glob[rows, hip]
        shin = d_mid @ glob[rows, knee]
        parent = glob[rows, 0]
        local = np.stack(
            [
                np.swapaxes(parent, -1, -2) @ thigh,
                np.swapaxes(thigh, -1, -2) @ shin,
                np.swapaxes(shin, -1, -2) @ glob[rows, ankle],
            ],
            axis=1,
        )
        quats[np.ix_(rows, [hip, knee, ankle])] = matrix_to_quat(local)
    stats = {
        "feet_corrected_fraction": corrected,
        "pelvis_lowered_max_m": float((motion.root_pos[:, 2] - root[:, 2]).max()),
    }
    return replace(motion, local_quats=quats, root_pos=root, contacts=contacts), stats


def postprocess(
    motion: Motion,
    traj: Trajectory,
    smoothing_sigma_frames: float = 1.0,
    contact_height_m: float = 0.05,
    contact_speed_mps: float = 0.2,
    blend_frames: int = 4,
) -> tuple[Motion, dict[str, Any]]:
    """The whole chain (module docstring); returns the final motion and its alignment figures."""
    aligned, figures = align_to_plan(motion, traj)
    resampled = resample_motion(aligned, traj.t, traj.frame)
    smoothed = smooth_motion(resampled, smoothing_sigma_frames)
    fk = forward_kinematics(smoothed.rest_joints, smoothed.local_quats, smoothed.root_pos)
    contacts = detect_contacts(fk[0], smoothed.rest_joints, traj.fps, contact_height_m, contact_speed_mps)
    if smoothed.contacts is not None:  # the generator's stance flags: a low, slow swing (a shuffle) is no contact
        contacts &= smoothed.contacts
    final, lock_stats = lock_feet(smoothed, contacts, blend_frames, fk)
    final.local_quats = final.local_quats / vector_norm(final.local_quats, keepdims=True)
    return final, {**{k: round(v, 6) for k, v in figures.items()}, **{k: round(v, 6) for k, v in lock_stats.items()}}
