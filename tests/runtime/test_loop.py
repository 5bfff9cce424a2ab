"""Collision counting, the recovery rule, outcomes and baselines on hand-built episodes."""

from __future__ import annotations

import numpy as np
import pytest

from song.config import RobotConfig
from song.runtime.avatars import AvatarCollider, body_proxy_points, count_inside_volume, proxy_poser
from song.runtime.loop import EpisodeRunner, run_episode
from song.runtime.policies import AStarPolicy, SocialPolicy, StraightPolicy, load_policy
from song.runtime.robot import Pose, integrate
from song.runtime.world import StaticWorld
from tests.runtime.helpers import episode, room_map, track


def _collider(ep, volume="sphere"):
    return AvatarCollider(ep.pedestrians, proxy_poser(ep.pedestrians), volume=volume)


def test_count_inside_volume_threshold() -> None:
    pts = np.array([[0.0, 0.0, 0.8], [0.1, 0.0, 0.8], [0.0, 0.19, 0.8], [0.0, 0.0, 1.05], [0.3, 0.0, 0.8]])
    assert count_inside_volume(pts, np.zeros(2), 0.2, 0.8) == 3
    assert count_inside_volume(pts, np.zeros(2), 0.2, 0.8, "cylinder") == 4
    with pytest.raises(ValueError):
        count_inside_volume(pts, np.zeros(2), 0.2, 0.8, "cube")


def test_robot_inside_torso_collides_and_half_metre_away_does_not() -> None:
    ped = track(0, (5.0, 3.0), (5.0, 3.0001))
    ep = episode(peds=[ped])
    collider = _collider(ep)
    inside = collider.count(0.0, np.array([5.0, 3.0]))
    assert inside > 5
    assert collider.count(0.0, np.array([5.0, 3.5])) == 0
    assert len(body_proxy_points()) > 100


def test_avatar_collision_ends_episode_as_human_failure() -> None:
    # a pedestrian walking straight at the robot's path; the straight policy does not care
    ped = track(0, (6.0, 3.0), (1.5, 3.0), speed=0.9)
    ep = episode(peds=[ped])
    result = run_episode(ep, StraightPolicy(), _collider(ep))
    assert result.outcome == "human" and result.max_gaussian_count > 5
    assert result.metrics.min_distance < 0.3


def test_wall_contact_restores_pose_counts_and_fails_after_five() -> None:
    ep = episode(start=(1.0, 3.0), goal=(8.0, 3.0), walls=[(2.0, 0.0, 2.2, 6.0)])
    runner = EpisodeRunner(ep, _collider(ep))
    outcome = None
    while outcome is None:
        outcome = runner.step(0.5, 0.0)
    result = runner.result()
    assert outcome == "obstacle" and result.obstacle_collisions == 5
    world = StaticWorld(ep.static_map)
    assert not world.collides(result.trajectory[:, :2], 0.2).any()  # every logged pose is a safe one
    assert ("reorient" in {kind for _, kind in result.events}) is False  # it kept moving until contact


def test_stuck_robot_is_reoriented_toward_open_space() -> None:
    ep = episode(
        start=(1.71, 3.0), goal=(8.0, 3.0), walls=[(2.0, 0.0, 2.2, 6.0)], robot=RobotConfig(max_obstacle_collisions=50)
    )
    runner = EpisodeRunner(ep, _collider(ep))
    for _ in range(12):
        runner.step(0.5, 0.0)
    assert runner.c_obs >= 10
    assert any(kind == "reorient" for _, kind in runner.events)
    assert abs(np.cos(runner.pose.yaw)) < 0.95  # no longer facing the wall head-on


def test_success_and_timeout_and_single_outcome() -> None:
    ep = episode(start=(1.0, 3.0), goal=(4.0, 3.0))
    result = run_episode(ep, StraightPolicy(), _collider(ep))
    assert result.outcome == "success"
    assert np.linalg.norm(result.trajectory[-1, :2] - ep.goal_xy) < 1.0
    assert result.metrics.length == pytest.approx(2.0, abs=0.06)
    robot = RobotConfig(max_steps=30, max_obstacle_collisions=99)
    far = episode(start=(1.0, 1.0), goal=(9.0, 5.0), walls=[(3.0, 0.0, 3.2, 5.0)], robot=robot)
    blocked = run_episode(far, StraightPolicy(), _collider(far))
    assert blocked.outcome == "timeout" and blocked.steps == 30


def test_unicycle_limits_and_arc() -> None:
    pose = integrate(Pose(0.0, 0.0, 0.0), 0.5, np.pi / 2, 1.0)
    radius = 0.5 / (np.pi / 2)
    np.testing.assert_allclose([pose.x, pose.y], [radius, radius], atol=1e-12)


def test_astar_follows_path_around_a_wall_and_social_avoids_people() -> None:
    walls = [(4.0, 0.0, 4.2, 4.0)]
    path = [(1.0, 2.0), (3.5, 5.0), (5.0, 5.0), (8.0, 2.0)]
    ep = episode(start=(1.0, 2.0), goal=(8.0, 2.0), walls=walls, path=path)
    assert run_episode(ep, StraightPolicy(), _collider(ep)).outcome != "success"
    assert run_episode(ep, AStarPolicy(), _collider(ep)).outcome == "success"
    ped = track(0, (7.5, 3.0), (1.0, 3.0), speed=0.7)
    crossing = episode(peds=[ped])
    assert run_episode(crossing, StraightPolicy(), _collider(crossing)).outcome == "human"
    social = run_episode(crossing, SocialPolicy(), _collider(crossing))
    assert social.outcome == "success" and social.metrics.min_distance > 0.45


def test_load_policy() -> None:
    assert isinstance(load_policy("astar"), AStarPolicy)
    assert isinstance(load_policy("song.runtime.policies:SocialPolicy"), SocialPolicy)
    with pytest.raises(Exception, match="unknown policy"):
        load_policy("nope")
    assert room_map().cells.dtype == np.uint8


def test_range_cast_hits_walls_and_people() -> None:
    from song.runtime.world import cast_circles

    world = StaticWorld(room_map(walls=[(7.0, 0.0, 7.2, 6.0)]))
    angles = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2])
    ranges = world.cast(np.array([5.0, 3.0]), angles, 5.0)
    # walls: x = 7.0 (east), y = 5.9 (north border), x = 0.1 (west, beyond 5 m), y = 0.1 (south)
    np.testing.assert_allclose(ranges, [2.0, 2.9, 4.9, 2.9], atol=0.05)
    people = cast_circles(np.array([5.0, 3.0]), angles, np.array([[6.0, 3.0]]), 0.25, 5.0)
    np.testing.assert_allclose(people, [0.75, 5.0, 5.0, 5.0], atol=1e-9)
