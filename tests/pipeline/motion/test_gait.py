"""Procedural gait on synthetic plans: the issue's quality targets as assertions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from song.config import MotionConfig
from song.geometry.rotations import quat_to_matrix, wrap_angle, yaw_of_matrix
from song.geometry.skeleton import JOINT_INDEX as J
from song.pipeline.motion import ProceduralGait
from song.pipeline.motion._quality_reference import foot_skating_reference
from song.pipeline.motion.gait import cadence_steps_per_s, generate_gait, sample_style
from song.pipeline.motion.postprocess import postprocess
from song.pipeline.motion.quality import foot_skating_ratio, motion_quality
from song.pipeline.motion.synthetic import synthetic_trajectories, trajectory_from_profiles

CFG = MotionConfig()
PLANS = synthetic_trajectories(10.0)


@pytest.fixture(scope="module")
def results():
    out = {}
    gen = ProceduralGait(CFG)
    for name, traj in PLANS.items():
        raw = gen.generate([traj], [""], [traj.ped_id + 100])[0]
        final, figures = postprocess(raw, traj)
        quality = motion_quality(
            final.joints,
            final.local_quats,
            final.rest_joints,
            final.contacts,
            final.t,
            traj.xy,
            traj.speed,
            raw.info["walk_ratio_m_s"],
            CFG.min_cadence_spm,
        )
        out[name] = (traj, raw, final, quality)
    return out


@pytest.mark.parametrize("name", list(PLANS))
def test_quality_targets(results, name):
    _, _, _, q = results[name]
    assert q["foot_skating_ratio"] <= 0.02
    assert q["penetration_p99_m"] <= 0.01
    assert q["contact_float_max_m"] <= 0.02
    assert q["root_error_mean_m"] <= 0.02 and q["root_error_max_m"] <= 0.05
    assert q["knee_flexion_min_deg"] >= -1.0  # never hyper-extends
    assert q["elbow_flexion_min_deg"] >= 0.0  # elbows bend one way
    assert q["cadence_error_max"] <= 0.10


def test_cadence_follows_walk_ratio_model(results):
    for name in ("straight_0.5", "straight_1.0", "straight_1.4"):
        traj, raw, _, q = results[name]
        assert q["cadence_strides"] >= 5
        speed = float(name.split("_")[1])
        expected = cadence_steps_per_s(np.array(speed), CFG.walk_ratio_m_s, CFG.min_cadence_spm)
        steady = traj.t > 2.0
        onsets = np.flatnonzero(raw.contacts[1:, 0] & ~raw.contacts[:-1, 0] & steady[1:]) + 1
        measured = 2.0 / np.median(np.diff(traj.t[onsets]))
        assert abs(measured / expected - 1) < 0.06
    assert cadence_steps_per_s(np.array(0.3), 0.38, 85.0) == pytest.approx(85 / 60)


def test_stance_is_sixty_percent_when_walking(results):
    traj, raw, _, _ = results["straight_1.0"]
    steady = traj.t > 2.0
    assert raw.contacts[steady].mean() == pytest.approx(0.6, abs=0.04)
    # single support alternates: never both feet in the air
    assert raw.contacts.any(axis=1).all()


def test_standing_idles_with_both_feet_planted(results):
    traj, raw, final, _ = results["standing"]
    joints = final.joints
    assert raw.contacts.all()
    for toe in (J["left_foot"], J["right_foot"]):
        assert np.ptp(joints[:, toe, :2], axis=0).max() < 1e-3
    # but the body is not frozen: breathing / look-around move the head a little
    assert np.ptp(joints[:, J["head"]], axis=0).max() > 0.002


def test_turning_on_the_spot_steps_round(results):
    traj, raw, final, _ = results["turn_on_spot"]
    joints = final.joints
    assert np.linalg.norm(final.root_pos[:, :2] - traj.xy, axis=1).max() < 0.03
    heading = yaw_of_matrix(quat_to_matrix(final.local_quats[:, 0]))
    assert np.abs(wrap_angle(heading[-1] - traj.yaw[-1])) < np.radians(10)
    # the feet turned with the body: foot direction (ankle → ball) follows the final heading
    foot = joints[-1, J["left_foot"], :2] - joints[-1, J["left_ankle"], :2]
    assert np.abs(wrap_angle(np.arctan2(foot[1], foot[0]) - traj.yaw[-1])) < np.radians(25)
    assert (~raw.contacts).any()  # it did step


def test_phase_is_continuous_and_motion_smooth(results):
    for name in ("stop_and_go", "walk_then_stop", "curve"):
        _, raw, _, _ = results[name]
        joints = raw.joints
        step = np.linalg.norm(np.diff(joints, axis=0), axis=-1).max()
        assert step < 0.2  # no jumps: nothing faster than 6 m/s (a swinging toe peaks near 5× walking speed)


def test_same_seed_same_bytes_and_styles_differ():
    traj = PLANS["curve"]
    gen = ProceduralGait(CFG)
    a = gen.generate([traj], [""], [5])[0]
    b = gen.generate([traj], [""], [5])[0]
    c = gen.generate([traj], [""], [6])[0]
    assert a.local_quats.tobytes() == b.local_quats.tobytes()
    assert a.root_pos.tobytes() == b.root_pos.tobytes()
    assert np.abs(a.joints - c.joints).max() > 0.01


def test_heights_are_seeded_within_range():
    heights = [sample_style(np.random.default_rng(s)).height_m for s in range(300)]
    assert min(heights) >= 1.5 and max(heights) <= 1.95
    assert np.std(heights) > 0.05


def test_skating_metric_matches_twin_and_detects_sliding():
    traj = PLANS["straight_1.0"]
    motion = generate_gait(traj, sample_style(np.random.default_rng(1)))
    joints = motion.joints
    assert foot_skating_ratio(joints, 30.0) == pytest.approx(foot_skating_reference(joints, 30.0))
    sliding = joints.copy()
    sliding[:, J["left_foot"], 2] = 0.02
    sliding[:, J["left_foot"], 0] = np.arange(len(joints)) * 0.04  # 1.2 m/s on the floor
    ratio = foot_skating_ratio(sliding, 30.0)
    assert ratio > 0.9 and ratio == pytest.approx(foot_skating_reference(sliding, 30.0))


def test_single_frame_and_reverse_heading():
    traj = trajectory_from_profiles(3, np.zeros(1), np.zeros(1), start=(0.0, 0.0, 2.0))
    motion = ProceduralGait(CFG).generate([traj], [""], [1])[0]
    final, _ = postprocess(motion, traj)
    assert final.local_quats.shape == (1, 24, 4)
    back = trajectory_from_profiles(4, np.full(120, 0.8), np.zeros(120), start=(0.0, 0.0, np.pi))
    final, _ = postprocess(ProceduralGait(CFG).generate([back], [""], [2])[0], back)
    assert final.joints[-1, 0, 0] < -2.0  # walked along −x


def test_yaw_flips_in_the_plan_become_bounded_turns():
    from song.pipeline.motion.types import MAX_TURN_RATE, Trajectory, body_heading

    n = 150
    t = np.arange(n) / 30.0
    yaw = np.where(np.arange(n) < 75, 0.0, np.pi - 0.01)  # a one-frame flip, as crowd plans have
    heading = body_heading(yaw, t)
    assert np.abs(np.diff(heading)).max() * 30 <= MAX_TURN_RATE + 1e-9
    assert heading[0] == 0.0 and heading[-1] == pytest.approx(np.pi - 0.01)
    assert heading[74] == pytest.approx(0.5 * (np.pi - 0.01), abs=0.15)  # centred on the flip
    slow = 0.5 * t
    assert np.allclose(body_heading(slow, t), slow)
    traj = Trajectory(
        ped_id=0, t=t, frame=np.arange(n, dtype=np.int32), xy=np.zeros((n, 2)), yaw=yaw, speed=np.zeros(n)
    )
    final, _ = postprocess(ProceduralGait(CFG).generate([traj], [""], [1])[0], traj)
    joints = final.joints
    assert np.linalg.norm(np.diff(joints, axis=0), axis=-1).max() < 0.1
    q = motion_quality(
        joints, final.local_quats, final.rest_joints, final.contacts, final.t, traj.xy, traj.speed, 0.38, 85
    )
    assert q["foot_skating_ratio"] <= 0.02


@pytest.fixture(scope="module")
def cycle_figures():
    from song.pipeline.motion.quality import gait_cycle_figures
    from song.pipeline.motion.synthetic import steady_walk

    out = {}
    for v in (0.8, 1.0, 1.3, 1.6):
        traj = steady_walk(v)
        raw = ProceduralGait(CFG).generate([traj], [""], [7])[0]
        final, _ = postprocess(raw, traj)
        out[v] = gait_cycle_figures(final.local_quats, final.contacts, final.t, traj.speed, final.joints)
    return out


def test_knee_and_hip_follow_the_normative_curves(cycle_figures) -> None:
    """Perry & Burnfield 2010 at 1.0-1.3 m/s: knee ≤ 8° at heel strike, a 10-25° loading-response wave,
    55-68° peak in swing; hip sagittal range 35-50°."""
    from song.pipeline.motion.quality import NORMATIVE

    for v in (1.0, 1.3):
        f = cycle_figures[v]
        for key in ("knee_heel_strike_deg", "knee_loading_peak_deg", "knee_swing_peak_deg", "hip_range_deg"):
            lo, hi = NORMATIVE[key]
            assert lo <= f[key] <= hi, (v, key, f)
        assert f["knee_heel_strike_deg"] + 5.0 < f["knee_loading_peak_deg"] < f["knee_swing_peak_deg"]


def test_pelvis_rotates_and_arms_swing_against_the_legs(cycle_figures) -> None:
    """Pelvic rotation ±3-6°; shoulder swing ±10-25° at 1.0-1.3 m/s, opposite to the same side's hip
    (Murray et al. 1967), and growing with speed."""
    from song.pipeline.motion.quality import NORMATIVE

    for v in (1.0, 1.3):
        f = cycle_figures[v]
        for key in ("pelvic_rotation_deg", "shoulder_swing_deg"):
            lo, hi = NORMATIVE[key]
            assert lo <= f[key] <= hi, (v, key, f)
    for f in cycle_figures.values():
        assert f["arm_hip_correlation"] < -0.8, f
    assert cycle_figures[1.6]["shoulder_swing_deg"] > cycle_figures[0.8]["shoulder_swing_deg"]


@pytest.mark.parametrize("turn_deg", [45, 90, 135, 180])
def test_no_foot_passes_through_the_other_in_turns(turn_deg: int) -> None:
    """Walking turns of 45-180° at 1.5 rad/s, 0.5-1.4 m/s: the feet never overlap by more than half."""
    from song.pipeline.motion.quality import FEET_CLASH_M, feet_gap

    n = 300
    frames = int(round(30 * np.radians(turn_deg) / 1.5))
    yaw_rate = np.zeros(n)
    yaw_rate[120 : 120 + frames] = np.radians(turn_deg) / (frames / 30.0)
    for v in (0.5, 1.0, 1.4):
        traj = trajectory_from_profiles(0, np.full(n, v), yaw_rate)
        for seed in (0, 2):
            final, _ = postprocess(ProceduralGait(CFG).generate([traj], [""], [seed])[0], traj)
            assert feet_gap(final.joints).min() >= FEET_CLASH_M, (v, seed)


def test_walk_ratio_and_cadence_follow_speed(cycle_figures) -> None:
    """Sekiya & Nagasaki 1998: walk ratio constant within 0.34-0.44 m·s; 100-120 steps/min at 1.3 m/s."""
    for v, f in cycle_figures.items():
        assert 0.34 <= f["walk_ratio_m_s"] <= 0.44, (v, f)
    assert 100.0 <= cycle_figures[1.3]["cadence_spm"] <= 120.0
    cadence = [cycle_figures[v]["cadence_spm"] for v in sorted(cycle_figures)]
    assert all(np.diff(cadence) > 0)  # faster walkers take faster steps too


def test_head_trunk_and_pelvis_turn_before_the_path() -> None:
    """Anticipatory steering: a 90° walking turn; the head leads by ~0.25 s, then the trunk, then the
    pelvis, none lagging (crowd yaw lags the path; the gait reads the direction from the positions)."""
    from song.pipeline.motion.quality import heading_leads
    from song.pipeline.motion.synthetic import trajectory_from_profiles

    n, start, frames = 300, 120, 32
    yaw_rate = np.zeros(n)
    yaw_rate[start : start + frames] = (np.pi / 2) / (frames / 30.0)
    traj = trajectory_from_profiles(0, np.full(n, 1.2), yaw_rate)
    lagging = dataclasses.replace(traj, yaw=np.concatenate([np.full(6, traj.yaw[0]), traj.yaw[:-6]]))  # 0.2 s late
    for plan in (traj, lagging):
        motion = ProceduralGait(CFG).generate([plan], [""], [5])[0]
        leads = heading_leads(motion.local_quats, motion.rest_joints, motion.root_pos, plan.xy, plan.t)
        assert 0.18 <= leads["head"] <= 0.32, leads
        assert leads["head"] > leads["spine3"] > leads["pelvis"] >= 0.1, leads


def test_repositioning_is_a_shuffle_not_a_full_step() -> None:
    """A standing pedestrian who moves 15 cm takes low shuffle steps (the ball of the foot clears the floor
    by ~3 cm, not the 10-13 cm of walking), which post-processing neither pins to the floor nor reads as
    skating."""
    n = 150
    speed = np.zeros(n)
    speed[45:75] = 0.15 * np.sin(np.linspace(0.0, np.pi, 30)) * np.pi / 2 / (30 / 30.0)  # 15 cm over 1 s
    traj = trajectory_from_profiles(0, speed, np.zeros(n))
    raw = ProceduralGait(CFG).generate([traj], [""], [2])[0]
    stepped = ~raw.contacts.all(axis=1)
    assert stepped.any()
    joints = raw.joints
    lift = max(
        (joints[:, J[f"{side}_foot"], 2] - raw.rest_joints[J[f"{side}_foot"], 2])[stepped].max()
        for side in ("left", "right")
    )
    assert 0.005 < lift < 0.04, lift
    final, _ = postprocess(raw, traj)
    assert np.abs(final.joints - raw.joints).max() < 0.02
    assert foot_skating_ratio(final.joints, 30.0) == 0.0
