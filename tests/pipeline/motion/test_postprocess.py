"""Post-processing: alignment, resampling, smoothing, contact detection and foot locking."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from song.geometry.rotations import quat_about_z, quat_angle, quat_mul, quat_to_matrix, yaw_of_matrix
from song.geometry.skeleton import JOINT_INDEX as J
from song.pipeline.motion import ProceduralGait
from song.pipeline.motion.postprocess import (
    align_to_plan,
    detect_contacts,
    lock_feet,
    postprocess,
    resample_motion,
    smooth_motion,
)
from song.pipeline.motion.quality import motion_quality, sole_gaps
from song.pipeline.motion.synthetic import synthetic_trajectories

PLANS = synthetic_trajectories(8.0)
RNG = np.random.default_rng(2)


@pytest.fixture(scope="module")
def walk():
    traj = PLANS["curve"]
    return traj, ProceduralGait().generate([traj], [""], [9])[0]


def test_align_removes_drift_but_keeps_sway(walk):
    traj, motion = walk
    n = motion.n_frames
    drift_xy = np.stack([np.linspace(0, 0.3, n), np.full(n, 0.05)], axis=-1)
    drifted = replace(
        motion,
        root_pos=motion.root_pos + np.concatenate([drift_xy, np.zeros((n, 1))], axis=1),
        local_quats=motion.local_quats.copy(),
    )
    drifted.local_quats[:, 0] = quat_mul(quat_about_z(np.linspace(0, 0.4, n)), motion.local_quats[:, 0])
    aligned, figures = align_to_plan(drifted, traj)
    assert figures["root_error_before_max_m"] > 0.25
    assert figures["root_error_after_max_m"] <= 0.02 + 1e-9
    aligned_clean, clean = align_to_plan(motion, traj)  # the gait's own pelvic rotation and turn lead: a few degrees
    assert figures["heading_error_after_mean_deg"] < clean["heading_error_after_mean_deg"] + 0.5
    assert figures["heading_error_before_mean_deg"] > 10.0
    yaw_fixed = yaw_of_matrix(quat_to_matrix(aligned.local_quats[:, 0]))
    yaw_orig = yaw_of_matrix(quat_to_matrix(aligned_clean.local_quats[:, 0]))
    assert np.abs(np.angle(np.exp(1j * (yaw_fixed - yaw_orig))))[30:-30].max() < np.radians(3)
    # the gait's lateral sway survives alignment
    sway = np.linalg.norm(aligned.root_pos[:, :2] - traj.xy, axis=1)
    assert sway.max() > 0.004


def test_resample_identity_and_half_rate(walk):
    _, motion = walk
    same = resample_motion(motion, motion.t, motion.frame)
    assert np.array_equal(same.local_quats, motion.local_quats)
    t = motion.t[::2]
    half = resample_motion(replace(motion, t=motion.t, frame=motion.frame), t, motion.frame[::2])
    assert np.allclose(half.root_pos, motion.root_pos[::2])
    assert quat_angle(half.local_quats, motion.local_quats[::2]).max() < 1e-6
    mid = resample_motion(motion, motion.t[:-1] + 0.5 / 30, motion.frame[:-1])
    expected = 0.5 * (motion.root_pos[:-1] + motion.root_pos[1:])
    assert np.allclose(mid.root_pos, expected)


def test_smoothing_reduces_jitter(walk):
    _, motion = walk
    noisy = replace(motion, root_pos=motion.root_pos + RNG.normal(scale=0.01, size=motion.root_pos.shape))
    smooth = smooth_motion(noisy, 1.5)
    assert np.abs(np.diff(smooth.root_pos, 2, axis=0)).mean() < 0.3 * np.abs(np.diff(noisy.root_pos, 2, axis=0)).mean()
    assert np.allclose(np.linalg.norm(smooth.local_quats, axis=-1), 1.0)


def test_contacts_agree_with_gait_stance():
    for name in ("straight_1.0", "stop_and_go", "turn_on_spot"):
        traj = PLANS[name]
        motion = ProceduralGait().generate([traj], [""], [3])[0]
        detected = detect_contacts(motion.joints, motion.rest_joints, 30.0)
        assert (detected == motion.contacts).mean() > 0.95


def test_lock_feet_removes_injected_sliding():
    traj = PLANS["straight_1.0"]
    motion = ProceduralGait().generate([traj], [""], [4])[0]
    contacts = motion.contacts.copy()
    # make the planted feet slide and sink: drift the whole body forward 0.15 m/s faster than planned
    n = motion.n_frames
    slide = np.zeros((n, 3))
    slide[:, 0] = np.arange(n) * 0.005
    slide[:, 2] = -0.015
    sliding = replace(motion, root_pos=motion.root_pos + slide)
    before = sliding.joints
    fixed, stats = lock_feet(sliding, contacts, blend_frames=4)
    after = fixed.joints
    for side, toe in enumerate((J["left_foot"], J["right_foot"])):
        speed_before = np.linalg.norm(np.diff(before[:, toe, :2], axis=0), axis=1)[
            contacts[1:, side] & contacts[:-1, side]
        ]
        speed_after = np.linalg.norm(np.diff(after[:, toe, :2], axis=0), axis=1)[
            contacts[1:, side] & contacts[:-1, side]
        ]
        assert speed_before.mean() > 0.004 and speed_after.max() < 1e-6
    gaps = sole_gaps(after, fixed.rest_joints)
    assert np.abs(gaps[contacts]).max() < 1e-6  # planted soles touch the floor
    assert gaps.min() > -1e-6  # and nothing is below it
    assert stats["feet_corrected_fraction"] > 0.5
    # bone lengths unchanged, knees still bend forwards
    q = motion_quality(after, fixed.local_quats, fixed.rest_joints, contacts, fixed.t, traj.xy, traj.speed, 0.38, 85)
    assert q["knee_flexion_min_deg"] > -1.0


@pytest.mark.parametrize("name", sorted(PLANS))
def test_postprocess_keeps_clean_motion_clean(name):
    """The procedural gait needs little cleaning: no joint moves 7 cm (up to 12 cm with the gait of
    2026-11-22 on these plans), the root stays within 2 cm of the plan."""
    traj = PLANS[name]
    for seed in (4, 8):
        motion = ProceduralGait().generate([traj], [""], [seed])[0]
        final, figures = postprocess(motion, traj)
        assert np.abs(final.joints - motion.joints).max() < 0.07
        assert figures["root_error_after_max_m"] <= 0.02
        assert final.contacts.shape == (motion.n_frames, 2)


def test_lock_feet_keeps_knees_forward_when_the_pelvis_turns_ahead_of_the_legs():
    """A pelvis turned 120° ahead of its legs (a sharp turn with the trunk leading) and the pelvis lowered
    by foot locking: the re-solved knees still bend forwards (checked against the pelvis alone, a swing
    knee was flipped backwards by up to 65° in crowd runs)."""
    from song.geometry.rotations import quat_about_z, quat_conj
    from song.pipeline.motion.quality import knee_elbow_flexion

    traj = PLANS["straight_1.0"]
    motion = ProceduralGait().generate([traj], [""], [3])[0]
    turn = quat_about_z(np.full(motion.n_frames, np.radians(120.0)))
    quats = motion.local_quats.copy()
    root = quats[:, 0]
    for hip in (J["left_hip"], J["right_hip"]):  # the thighs keep their world orientation
        quats[:, hip] = quat_mul(quat_mul(quat_mul(quat_conj(root), quat_conj(turn)), root), quats[:, hip])
    quats[:, 0] = quat_mul(turn, root)
    turned = replace(motion, local_quats=quats)
    sunk = replace(turned, root_pos=turned.root_pos + np.array([0.0, 0.0, 0.03]))  # the feet float 3 cm: locked down
    fixed, stats = lock_feet(sunk, motion.contacts, blend_frames=4)
    assert stats["feet_corrected_fraction"] > 0.5
    before = np.degrees(knee_elbow_flexion(turned.local_quats)["knee"])
    after = np.degrees(knee_elbow_flexion(fixed.local_quats)["knee"])
    assert before.min() >= 0.0 and after.min() >= 0.0
