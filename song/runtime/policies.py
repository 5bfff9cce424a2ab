"""The ``Policy`` protocol and the built-in baselines (paper Table 2 rows).

- ``straight``: turn toward the goal and drive (blind to walls and people).
- ``astar``: pure pursuit of the episode's smoothed A* path (blind to people).
- ``social``: privileged upper bound: the A* path plus a velocity-obstacle rollout planner that
  sees every pedestrian's position and velocity and the static map (like the paper's teleop row).
- ``depth``: the vision baseline (:mod:`song.runtime.depth_policy`): the depth image, the goal and its
  own velocity only.

A policy declares the sensors it reads (``sensors``); the robot's limits, its radius and the
pedestrians' body radius come from the episode's runtime parameters (the release's recorded values),
never from constants here. A user's policy loads with ``--policy module:Class``.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from song import plugins
from song.config import RobotConfig
from song.datasets.bench.types import Episode
from song.errors import SongError
from song.geometry.rotations import wrap_angle
from song.runtime.world import StaticWorld

# soft cost on predicted gaps to people below PROXIMITY_M (m); at 1.0 m the robot preferred turning on the
# spot to passing a standing person at 0.8 m and timed out in doorways (demo: easy SR 89.6 % → 97.9 % at 0.8 m)
PROXIMITY_M, PROXIMITY_WEIGHT = 0.8, 0.5
WALL_MARGIN_M = 0.03  # the social planner keeps this much more than its radius from walls
DEFAULT_SENSORS = ("state", "scan")  # what a user policy that declares no sensors receives


@runtime_checkable
class Policy(Protocol):
    """A robot policy: ``reset`` once per episode, then ``act`` each 10 Hz step → (v m/s, ω rad/s).

    Attributes:
        sensors: names of the sensors whose outputs ``act`` reads (``observation[name]``).
    """

    sensors: tuple[str, ...]

    def reset(self, episode: Episode) -> None:
        """Prepare for ``episode`` (its map, goal, path, and ``episode.params`` limits)."""
        ...

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """The command (v m/s, ω rad/s) for this step's ``{sensor: output}`` observation."""
        ...


def policy_sensors(policy: object) -> tuple[str, ...]:
    """The sensors a policy reads.

    A policy declaring none gets ``state`` + ``scan`` (+ ``pedestrians`` when it sets the older
    ``privileged = True``).
    """
    declared = getattr(policy, "sensors", None)
    if declared:
        if (
            isinstance(declared, str)
            or not isinstance(declared, (list, tuple))
            or not all(isinstance(name, str) for name in declared)
        ):
            raise SongError(
                f"policy {type(policy).__name__}: sensors must be a tuple of sensor names, not {declared!r}"
            )
        return tuple(declared)
    return (*DEFAULT_SENSORS, "pedestrians") if getattr(policy, "privileged", False) else DEFAULT_SENSORS


def policy_info(policy: object) -> dict[str, Any]:
    """What results record about how a policy is driven: ``{"policy_kind": "commands"}``, or a tracker's description."""
    from song.runtime.waypoints import PurePursuitTracker

    return policy.describe() if isinstance(policy, PurePursuitTracker) else {"policy_kind": "commands"}


def steer_to(bearing: float, robot: RobotConfig, gain: float = 2.0, turn_in_place: float = 0.6) -> tuple[float, float]:
    """Drive toward a bearing (rad, robot frame) within the robot's limits: turn on the spot when it is far off."""
    max_w = float(np.deg2rad(robot.max_yaw_rate_deg_s))
    omega = float(np.clip(gain * bearing, -max_w, max_w))
    v = 0.0 if abs(bearing) > turn_in_place else robot.max_speed_mps * float(np.cos(bearing)) ** 2
    return v, omega


class StraightPolicy:
    """Turn toward the goal and drive."""

    sensors = ("state",)

    def reset(self, episode: Episode) -> None:
        """Remember the robot's limits."""
        self.robot = episode.params.robot

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """Steer at the goal's bearing."""
        return steer_to(float(observation["state"]["goal_polar"][1]), self.robot)


class PathFollower:
    """Pure pursuit along a polyline with a monotone progress index."""

    def __init__(self, path: np.ndarray, lookahead: float = 0.7) -> None:
        self.path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        seg = np.linalg.norm(np.diff(self.path, axis=0), axis=1)
        self.arc = np.concatenate([[0.0], np.cumsum(seg)])
        self.lookahead = lookahead
        self.progress = 0.0

    def point_at(self, s: float) -> np.ndarray:
        """The point at arc length ``s`` (clamped to the path)."""
        s = float(np.clip(s, 0.0, self.arc[-1]))
        return np.array([np.interp(s, self.arc, self.path[:, 0]), np.interp(s, self.arc, self.path[:, 1])])

    def target(self, xy: np.ndarray) -> np.ndarray:
        """The lookahead point beyond the robot's projection on the path (progress never goes back)."""
        if len(self.path) < 2:
            return self.path[-1]
        samples = np.linspace(self.progress, min(self.progress + 2.0, self.arc[-1]), 41)
        points = np.column_stack(
            [np.interp(samples, self.arc, self.path[:, 0]), np.interp(samples, self.arc, self.path[:, 1])]
        )
        self.progress = float(samples[np.argmin(np.linalg.norm(points - xy, axis=1))])
        return self.point_at(self.progress + self.lookahead)


def _pose(observation: dict[str, Any]) -> np.ndarray:
    return np.asarray(observation["state"]["pose"], dtype=np.float64)


def bearing_to(pose: np.ndarray, point: np.ndarray) -> float:
    """Bearing (rad, robot frame) of a world point from a pose (x, y, yaw)."""
    rel = point - pose[:2]
    return float(wrap_angle(np.arctan2(rel[1], rel[0]) - pose[2]))


def _guidance(episode: Episode, lookahead: float) -> PathFollower:
    path = episode.path if len(episode.path) >= 2 else np.vstack([episode.start_xy, episode.goal_xy])
    return PathFollower(np.vstack([path, episode.goal_xy]), lookahead=lookahead)


class AStarPolicy:
    """Follow the episode's smoothed A* path (blind to people)."""

    sensors = ("state", "map")  # the map entitles it to the floor plan and the planned path

    def reset(self, episode: Episode) -> None:
        """Start following the episode's path."""
        self.robot = episode.params.robot
        self.follower = _guidance(episode, lookahead=0.35)

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """Pure pursuit of the path."""
        pose = _pose(observation)
        return steer_to(bearing_to(pose, self.follower.target(pose[:2])), self.robot, turn_in_place=0.4)


class SocialPolicy:
    """Privileged rollout planner: A* guidance + avoidance of predicted pedestrians and walls.

    Each step it rolls out a grid of constant (v, ω) commands for ``horizon`` seconds against the
    pedestrians' constant-velocity predictions and the clearance field, discards commands that come
    closer than the safety distances, and picks the one that best approaches the pure-pursuit target.
    """

    sensors = ("state", "map", "pedestrians")

    def __init__(self, horizon: float = 2.0, dt: float = 0.1, safety: float = 0.2) -> None:
        self.horizon, self.dt, self.safety = horizon, dt, safety

    def reset(self, episode: Episode) -> None:
        """Build the command grid for the robot's limits and the clearance field of the map."""
        params = episode.params
        self.robot_radius = params.robot.radius_m
        self.body_radius = params.pedestrian_radius_m
        max_w = float(np.deg2rad(params.robot.max_yaw_rate_deg_s))
        v = np.linspace(0.0, params.robot.max_speed_mps, 6)
        w = np.linspace(-max_w, max_w, 11)
        self.commands = np.array([(a, b) for a in v for b in w])
        self.world = StaticWorld(episode.static_map)
        self.follower = _guidance(episode, lookahead=1.0)

    def _rollouts(self, x: float, y: float, yaw: float) -> np.ndarray:
        steps = int(round(self.horizon / self.dt))
        v, w = self.commands[:, 0:1], self.commands[:, 1:2]
        k = np.arange(1, steps + 1)[None, :] * self.dt
        heading = yaw + w * k
        safe_w = np.where(np.abs(w) < 1e-9, 1.0, w)
        xs = np.where(np.abs(w) < 1e-9, x + v * k * np.cos(yaw), x + v / safe_w * (np.sin(heading) - np.sin(yaw)))
        ys = np.where(np.abs(w) < 1e-9, y + v * k * np.sin(yaw), y - v / safe_w * (np.cos(heading) - np.cos(yaw)))
        return np.stack([xs, ys], axis=-1)  # (C, K, 2)

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """The safe rollout command that best approaches the pure-pursuit target."""
        pose = _pose(observation)
        target = self.follower.target(pose[:2])
        traj = self._rollouts(*pose)
        clearance = self.world.clearance_at(traj).min(axis=1)
        wall_ok = clearance > self.robot_radius + WALL_MARGIN_M
        cost = np.linalg.norm(traj[:, -1] - target, axis=1) + 0.3 * np.linalg.norm(traj[:, 3] - target, axis=1)
        table = np.asarray(observation["pedestrians"], dtype=np.float64)
        peds = table[table[:, 4] > 0.5, :4]
        if len(peds):
            k = np.arange(1, traj.shape[1] + 1) * self.dt
            future = peds[None, :, :2] + k[:, None, None] * peds[None, :, 2:]  # (K, P, 2)
            gaps = np.linalg.norm(traj[:, :, None, :] - future[None], axis=-1)  # (C, K, P)
            # near-term predictions matter most; distant ones are discounted
            weights = np.exp(-k / 1.5)[None, :, None]
            closest = gaps.min(axis=(1, 2))
            people_ok = closest > self.robot_radius + self.body_radius + self.safety
            cost = cost + PROXIMITY_WEIGHT * (weights * np.clip(PROXIMITY_M - gaps, 0.0, None)).sum(axis=(1, 2))
        else:
            closest = np.full(len(traj), np.inf)
            people_ok = np.ones(len(traj), dtype=bool)
        ok = wall_ok & people_ok
        if not ok.any():  # no safe command: keep as far from people and walls as possible
            score = np.minimum(closest, 10.0) + np.where(wall_ok, 1.0, 0.0)
            best = int(np.argmax(score))
        else:
            best = int(np.argmin(np.where(ok, cost, np.inf)))
        return float(self.commands[best, 0]), float(self.commands[best, 1])


def _depth_policy() -> Policy:
    from song.runtime.depth_policy import DepthPolicy

    return DepthPolicy()


class AStarWaypoints:
    """``astar`` as a waypoint policy: every 0.5 s, the next 2 m of the episode's A* path in the robot frame."""

    sensors = ("state", "map")
    rate_hz = 2.0

    def reset(self, episode: Episode) -> None:
        """Start following the episode's path."""
        self.follower = _guidance(episode, lookahead=0.0)

    def plan(self, observation: dict[str, Any]) -> np.ndarray:
        """Eight waypoints 0.25 m apart along the path ahead of the robot's projection on it."""
        pose = _pose(observation)
        self.follower.target(pose[:2])  # advances the projection
        ahead = np.array([self.follower.point_at(self.follower.progress + 0.25 * k) for k in range(1, 9)])
        rel = ahead - pose[:2]
        c, s = np.cos(pose[2]), np.sin(pose[2])
        return np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])


def _depth_waypoints() -> object:
    from song.runtime.depth_policy import DepthWaypoints

    return DepthWaypoints()


for _name, _factory in (("straight", StraightPolicy), ("astar", AStarPolicy), ("social", SocialPolicy),
                        ("depth", _depth_policy), ("astar_waypoints", AStarWaypoints),
                        ("depth_waypoints", _depth_waypoints)):  # fmt: skip
    plugins.add("policy", _name, _factory)
BASELINES = ("straight", "astar", "social", "depth")


def load_policy(name: str) -> Policy:
    """A ``policy`` plugin by name (a baseline, a registered plugin, ``module:Class`` or ``file.py:Class``).

    The plugin is called with no arguments; the result must have ``reset(episode)`` and ``act(observation)``,
    or ``plan(observation)`` and ``rate_hz`` (a waypoint policy, returned wrapped in its tracker:
    :mod:`song.runtime.waypoints`).
    """
    factory = plugins.lookup("policy", name)
    try:
        policy = factory()
    except Exception as exc:  # the user's __init__ failed: one line, naming the policy
        raise SongError(f"cannot create policy '{name}': {type(exc).__name__}: {exc}") from exc
    from song.runtime.waypoints import PurePursuitTracker, is_waypoint_policy

    if callable(getattr(policy, "reset", None)) and is_waypoint_policy(policy):
        return PurePursuitTracker(policy)
    if not (callable(getattr(policy, "reset", None)) and callable(getattr(policy, "act", None))):
        raise SongError(f"policy '{name}' must define reset(episode) and act(observation) (or plan(observation))")
    return policy
