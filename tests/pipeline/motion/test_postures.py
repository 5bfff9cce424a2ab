"""Hands resting on counters, desks and tables: the planar arm solve, the gait's posture, the stage's stays."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from song.config import MotionConfig
from song.datasets.scenes.model import SceneObject
from song.geometry.skeleton import JOINT_INDEX as J
from song.pipeline.motion.gait import generate_gait, style_for
from song.pipeline.motion.postures import (
    INTO_SHELF_M,
    ONTO_SURFACE_M,
    PALM_M,
    arm_on_surface,
    browse_plan,
    is_shelf,
    is_surface,
    shelf_track,
    surface_track,
)
from song.pipeline.motion.types import Trajectory, true_runs

FPS = 30


def test_planar_arm_solve_puts_the_hand_on_target_or_declines() -> None:
    # close to a high counter (the upper arm back), a mid one, farther and higher, and one out of reach
    edge, height = np.array([0.25, 0.3, 0.35, 0.9]), np.array([1.1, 1.0, 1.05, 1.0])
    shoulder, upper, fore = np.array([0.02, 1.43]), 0.29, 0.34
    flex_s, flex_e, possible = arm_on_surface(edge, height, shoulder, upper, fore)
    np.testing.assert_array_equal(possible, [True, True, True, False])
    assert flex_s[0] < 0 < flex_s[1]
    # forward kinematics of the two planar links from the shoulder (angles from straight down)
    hand_x = shoulder[0] + upper * np.sin(flex_s) + fore * np.sin(flex_s + flex_e)
    hand_z = shoulder[1] - upper * np.cos(flex_s) - fore * np.cos(flex_s + flex_e)
    np.testing.assert_allclose(hand_x[possible], (edge + ONTO_SURFACE_M)[possible], atol=1e-9)
    np.testing.assert_allclose(hand_z[possible], (height + PALM_M)[possible], atol=1e-9)
    assert (flex_e[possible] > 0).all() and (flex_s[~possible] == 0).all()


def _standing(surface: np.ndarray) -> Trajectory:
    n = len(surface)
    return Trajectory(0, np.arange(n) / FPS, np.arange(n, dtype=np.int32), np.zeros((n, 2)), np.zeros(n), np.zeros(n),
                      surface)  # fmt: skip


@pytest.mark.parametrize(("edge", "height"), [(0.2, 1.0), (0.35, 1.0), (0.3, 1.15), (0.3, 0.95), (0.45, 0.9)])
def test_gait_rests_both_hands_on_a_reachable_surface_and_clears_its_edge(edge: float, height: float) -> None:
    n = 240
    surface = np.full((n, 2), np.nan)
    surface[60:180] = (edge, height)
    rested = 0
    for seed in range(5):
        motion = generate_gait(_standing(surface), style_for(seed, MotionConfig()))
        joints, rots = motion.fk()
        hands = joints[:, [J["left_hand"], J["right_hand"]]]
        if np.abs(hands[120, :, 2] - height - PALM_M).max() < 0.005:  # this body reaches it
            rested += 1
            np.testing.assert_allclose(hands[90:150, :, 0], edge + ONTO_SURFACE_M, atol=0.005)
            np.testing.assert_allclose(hands[90:150, :, 2], height + PALM_M, atol=0.005)
            palms = rots[:, [J["left_hand"], J["right_hand"]]] @ np.array([0.0, 0.0, -1.0])  # T-pose palms face down
            assert (palms[90:150, :, 2] < -0.9).all()  # flat on the surface
            assert (np.abs(palms[:30, :, 1]) > 0.9).all()  # hanging: facing the thighs
        beyond = hands[..., 0] > edge + 0.005  # over the surface: the mid-palm stays above its top
        assert (hands[..., 2][beyond] >= height + 0.01).all()
        assert (hands[:30, :, 2] < 0.95).all() and (hands[-20:, :, 2] < 0.95).all()  # arms down before and after
    assert rested >= 3


@pytest.mark.parametrize("body_m", [1.5, 1.65, 1.8, 1.95])
def test_bending_at_the_hips_every_adult_reaches_a_counter_from_the_crowds_spots(body_m: float) -> None:
    """A 0.9 m counter 0.45 m away (the crowd stands 0.4-0.5 m from objects): both hands land on it, the
    pelvis tilts forward while they rest (the hips take part of the lean) and is upright again after."""
    n = 240
    surface = np.full((n, 2), np.nan)
    surface[60:180] = (0.45, 0.9)
    motion = generate_gait(_standing(surface), replace(style_for(0, MotionConfig()), height_m=body_m))
    joints, rots = motion.fk()
    hands = joints[:, [J["left_hand"], J["right_hand"]]]
    np.testing.assert_allclose(hands[90:150, :, 2], 0.9 + PALM_M, atol=0.005)
    np.testing.assert_allclose(hands[90:150, :, 0], 0.45 + ONTO_SURFACE_M, atol=0.005)
    tilt = np.degrees(np.arcsin(rots[:, J["pelvis"], 0, 2]))  # the pelvis's up axis, forward component
    assert (tilt[90:150] > 5.0).all()
    assert (np.abs(tilt[:30]) < 2.0).all() and (np.abs(tilt[-20:]) < 2.0).all()
    beyond = hands[..., 0] > 0.45 + 0.005
    assert (hands[..., 2][beyond] >= 0.9 + 0.01).all()


def test_a_low_table_takes_the_hands_of_short_bodies_only_and_no_lean_without_them() -> None:
    """A 0.75 m table 0.4 m away: within reach bending ≤ 45° for a 1.55 m body; a 1.9 m body stands upright
    and looks down at it."""
    n = 240
    surface = np.full((n, 2), np.nan)
    surface[60:180] = (0.4, 0.75)
    for body_m, reaches in ((1.55, True), (1.9, False)):
        motion = generate_gait(_standing(surface), replace(style_for(0, MotionConfig()), height_m=body_m))
        joints, rots = motion.fk()
        hands = joints[:, [J["left_hand"], J["right_hand"]], 2]
        on = np.abs(hands[90:150] - 0.75 - PALM_M).max() < 0.005
        assert on == reaches
        tilt = np.degrees(np.arcsin(rots[:, J["pelvis"], 0, 2]))
        assert ((tilt[90:150] > 5.0).all()) == reaches
        down = np.degrees(np.arcsin(-(rots[:, J["head"]] @ np.array([1.0, 0.0, 0.0]))[:, 2]))
        assert (down[90:150] > down[:30].max() + 10.0).all()


@pytest.mark.parametrize(
    ("track", "accept", "kind", "others", "stop_x"),
    [
        (surface_track, is_surface, ("counter", "furniture", 1.0), [("shelf", "furniture", 1.8), ("desk", "furniture", 0.5)], 0.7),
        (shelf_track, is_shelf, ("shelf", "storage", 1.9), [("shelving unit", "storage", 0.7), ("counter", "furniture", 1.0)], 0.55),
    ],
)  # fmt: skip
def test_stays_become_posture_frames_only_at_their_objects(track, accept, kind, others, stop_x: float) -> None:
    """Walking at 0.5 m/s to a spot short of a 1 m square object (its front at x = 1), then standing there."""
    square = [(1.0, -0.5), (2.0, -0.5), (2.0, 0.5), (1.0, 0.5)]
    objects = {
        f"o{k}": SceneObject(id=f"o{k}", label=label, category=category, footprint=square, z_max=top)
        for k, (label, category, top) in enumerate([kind, *others])
    }
    assert [accept(o) for o in objects.values()] == [True, False, False]
    n, arrive = 300, int(round(stop_x / 0.5 * FPS))
    xy = np.zeros((n, 2))
    xy[:, 0] = np.clip(np.arange(n) / FPS * 0.5, 0.0, stop_x)
    speed = np.r_[np.full(arrive, 0.5), np.zeros(n - arrive)]
    stays = track(xy, speed, FPS, [("o0", (stop_x, 0.0), 0.3)], objects)
    held = np.isfinite(stays[:, 0])
    assert held[100:250].all() and not held[:arrive].any() and not held[-10:].any()  # settled first, off before the end
    np.testing.assert_allclose(stays[held], [[1.0 - stop_x, kind[2]]] * int(held.sum()))
    assert track(xy, speed, FPS, [("o1", (stop_x, 0.0), 0.3), ("o2", (stop_x, 0.0), 0.3)], objects) is None


def _browsing(n: int = 600) -> Trajectory:
    shelf = np.full((n, 2), np.nan)
    shelf[60:540] = (0.45, 1.9)
    return Trajectory(3, np.arange(n) / FPS, np.arange(n, dtype=np.int32), np.zeros((n, 2)), np.zeros(n),
                      np.zeros(n), None, shelf)  # fmt: skip


def test_browse_plan_is_deterministic_and_touches_only_at_reachable_points() -> None:
    traj = _browsing()
    a, b, c = (browse_plan(traj.shelf, FPS, seed) for seed in (3, 3, 4))
    for name in ("on", "look", "reach", "left"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.look, c.look)
    for plan in (a, c):
        held = np.isfinite(traj.shelf[:, 0])
        assert (plan.reach[~held] == 0.0).all() and (plan.on[:20] < 0.01).all() and (plan.on[-20:] < 0.01).all()
        assert (np.abs(plan.look[held, 0]) <= 0.6).all() and (plan.look[held, 1] <= 1.8).all()
        touching = plan.reach > 0.0
        assert (plan.left[touching] == (plan.look[touching, 0] >= 0.0)).all()  # the hand on the side looked at
        assert (np.abs(plan.look[touching, 0]) <= 0.35).all()
        assert (np.abs(np.diff(plan.look[:, 1])) < 0.1).all()  # the gaze moves, it does not jump


def test_browsing_turns_the_head_along_the_shelf_and_a_hand_touches_an_item() -> None:
    """A 16 s stay at a shelf 0.45 m away: the head looks left, right, up and down within its limits, a
    hand touches the shelf's front where the gaze is and never goes deep into it, arms hang outside."""
    traj = _browsing()
    plan = browse_plan(traj.shelf, FPS, traj.ped_id)
    assert (plan.reach >= 0.999).any()
    joints, rots = generate_gait(traj, style_for(3, MotionConfig())).fk()
    face = rots[:, J["head"]] @ np.array([1.0, 0.0, 0.0])
    yaw, down = np.degrees(np.arctan2(face[:, 1], face[:, 0])), np.degrees(np.arcsin(-face[:, 2]))
    assert yaw[60:540].max() > 20.0 and yaw[60:540].min() < -20.0 and (np.abs(yaw) <= 45.5).all()
    assert down[60:540].max() - down[60:540].min() > 20.0
    hands = joints[:, [J["left_hand"], J["right_hand"]]]
    side = np.where(plan.left, 0, 1)
    full = np.flatnonzero(plan.reach >= 0.999)
    touch = hands[full, side[full]]
    np.testing.assert_allclose(touch[:, 0], 0.45 + INTO_SHELF_M, atol=0.04)
    np.testing.assert_allclose(touch[:, 2], plan.look[full, 1], atol=0.06)
    grip = rots[full, np.where(plan.left[full], J["left_hand"], J["right_hand"])]
    medial = np.where(plan.left[full], -1.0, 1.0)  # the palm (T-pose -z) faces the body's midline
    assert ((grip @ np.array([0.0, 0.0, -1.0]))[:, 1] * medial > 0.9).all()
    assert (hands[..., 0] <= 0.45 + INTO_SHELF_M + 0.02).all()
    assert (hands[:50, :, 2] < 1.0).all() and (hands[-50:, :, 2] < 1.0).all()
    still = plan.reach == 0.0  # between touches both arms hang
    assert (hands[still, :, 2] < 1.0).all()


def test_sample_crowds_rest_hands_on_counters(sample_run) -> None:
    """On the sample scenes' crowds, every stay at a counter of 0.9 m or more within 0.5 m (every adult
    height reaches it bending at the hips) has both hands on it at its middle, and most stays at surfaces
    of standing-work height (top ≥ 0.8 m) do; no hand jumps between frames."""
    from song.datasets.run import SceneFolder, read_intents
    from song.datasets.scenes import load_scene_package
    from song.pipeline.motion.stage import read_trajectories, with_stays
    from tests.conftest import SAMPLES

    counters, standing_work = [], []
    for scene in sorted((sample_run / "scenes").iterdir()):
        folder = SceneFolder(scene)
        objects = load_scene_package(SAMPLES / scene.name).semantic_map.object_by_id()
        trajectories = with_stays(read_trajectories(folder.crowd), read_intents(folder.intents).by_id(), objects)
        for traj in trajectories:
            if traj.surface is None:
                continue
            held = np.isfinite(traj.surface[:, 0])
            assert (traj.speed[held] < 0.01).all()  # only while standing
            joints = generate_gait(traj, style_for(traj.ped_id, MotionConfig())).joints
            hands = joints[:, [J["left_hand"], J["right_hand"]]]
            assert np.linalg.norm(np.diff(hands, axis=0), axis=-1).max() < 0.12  # no frame jumps (< 3.6 m/s)
            for lo, hi in true_runs(held):
                middle = (lo + hi) // 2
                edge, top = traj.surface[middle]
                on = np.abs(joints[middle, [J["left_hand"], J["right_hand"]], 2] - top - PALM_M).max() < 0.01
                if top >= 0.8:
                    standing_work.append(on)
                if top >= 0.9 and edge <= 0.5:
                    counters.append(on)
    assert len(counters) >= 10 and all(counters)
    assert np.mean(standing_work) >= 0.85


def test_sample_crowds_browse_shelves(sample_run) -> None:
    """On the sample scenes' crowds, pedestrians stay at shelves long enough to browse, some touch items, and
    no hand jumps between frames."""
    from song.datasets.run import SceneFolder, read_intents
    from song.datasets.scenes import load_scene_package
    from song.pipeline.motion.stage import read_trajectories, with_stays
    from tests.conftest import SAMPLES

    browsing = touches = 0
    for scene in sorted((sample_run / "scenes").iterdir()):
        folder = SceneFolder(scene)
        objects = load_scene_package(SAMPLES / scene.name).semantic_map.object_by_id()
        for traj in with_stays(read_trajectories(folder.crowd), read_intents(folder.intents).by_id(), objects):
            if traj.shelf is None:
                continue
            held = np.isfinite(traj.shelf[:, 0])
            assert (traj.speed[held] < 0.01).all()
            if traj.surface is not None:  # a stay is at a surface or at a shelf, never both
                assert not (held & np.isfinite(traj.surface[:, 0])).any()
            browsing += 1
            touches += int((browse_plan(traj.shelf, traj.fps, traj.ped_id).reach >= 0.999).any())
            joints = generate_gait(traj, style_for(traj.ped_id, MotionConfig())).joints
            hands = joints[:, [J["left_hand"], J["right_hand"]]]
            assert np.linalg.norm(np.diff(hands, axis=0), axis=-1).max() < 0.12  # no frame jumps (< 3.6 m/s)
    assert browsing >= 5 and touches >= 2
