"""Waypoint policies: models that predict a short trajectory, tracked by a controller at the control rate.

Published vision navigation models (NavDP, iPlanner, ViNT, NoMaD) output a few waypoints ahead of the
robot rather than a velocity command, each at its own rate. A *waypoint policy* has the same
``sensors`` and ``reset(episode)`` as a :class:`~song.runtime.policies.Policy` but, instead of ``act``,

- ``rate_hz``: how often it is queried (at most the control rate);
- ``plan(observation) -> array (K, 2)`` (or ``(K, 3)`` / ``(K, 4)``: extra columns such as heading and
  time are accepted and not used): waypoints in the robot frame at the time of the query (x forward,
  y left, metres), ordered along the way.

:func:`song.runtime.policies.load_policy` wraps such an object in a :class:`PurePursuitTracker`, which
is an ordinary 10 Hz policy: ``song eval``, ``song collect``, the Gymnasium env and ``--isolate`` take
it as they take any other.

The tracker is regulated pure pursuit (Coulter 1992; the curvature-regulated speed of Macenski et al.
2023, "Regulated Pure Pursuit", as in Nav2). It was chosen over a small MPC because the waypoints of
these models are already kinematically smooth, the robot is a unicycle with symmetric limits, and pure
pursuit has one parameter a user can reason about (the lookahead) and no solver whose failures would
be scored as the policy's. Per step, with the waypoints fixed in the world at the pose of the query:

1. the robot's projection on the polyline advances monotonically; the target is the point one
   lookahead distance further along it (the last waypoint when the polyline ends sooner);
2. with the target at (x, y) in the robot frame and L² = x² + y², the curvature is κ = 2y / L²;
3. the speed is the robot's limit, reduced so that |v κ| stays within the yaw-rate limit, and by the
   remaining distance near the last waypoint; a target more than 60° off the heading turns on the spot;
4. ω = v κ (or the turn on the spot), clipped to the yaw-rate limit; v changes by at most
   ``max_accel_mps2`` / control rate per step (the runtime applies commands instantly; this keeps the
   tracked motion as smooth as a real base would make it).

Results of a waypoint policy record its rate and this controller (:meth:`PurePursuitTracker.describe`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from song.datasets.bench.types import Episode
from song.errors import SongError
from song.geometry.rotations import wrap_angle

TURN_IN_PLACE_RAD = np.deg2rad(60.0)


def is_waypoint_policy(policy: object) -> bool:
    """Whether ``policy`` plans waypoints (has ``plan`` and no ``act``)."""
    return callable(getattr(policy, "plan", None)) and not callable(getattr(policy, "act", None))


def _waypoints(value: Any, name: str) -> np.ndarray:
    """The (K, 2) robot-frame positions of a ``plan`` reply, or a one-line error."""
    try:
        points = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SongError(f"waypoint policy {name}: plan() returned {type(value).__name__}, not an array") from exc
    if points.ndim != 2 or points.shape[0] < 1 or not 2 <= points.shape[1] <= 4:
        raise SongError(f"waypoint policy {name}: plan() must return (K, 2..4) waypoints, got shape {points.shape}")
    if not np.isfinite(points[:, :2]).all():
        raise SongError(f"waypoint policy {name}: plan() returned non-finite waypoints")
    return points[:, :2]


class PurePursuitTracker:
    """A waypoint policy driven at the control rate by regulated pure pursuit (see the module docstring).

    Args:
        policy: the waypoint policy (``sensors``, ``rate_hz``, ``reset``, ``plan``).
        lookahead_m: pure-pursuit lookahead distance.
        max_accel_mps2: largest change of the linear speed per second.
    """

    def __init__(self, policy: Any, lookahead_m: float = 0.5, max_accel_mps2: float = 1.0) -> None:
        self.policy = policy
        self.name = type(policy).__name__
        rate = getattr(policy, "rate_hz", None)
        if not isinstance(rate, (int, float)) or not np.isfinite(rate) or rate <= 0:
            raise SongError(f"waypoint policy {self.name}: rate_hz must be a positive number, not {rate!r}")
        self.rate_hz = float(rate)
        declared = tuple(getattr(policy, "sensors", None) or ("state",))
        self.sensors = declared if "state" in declared else ("state", *declared)
        self.lookahead_m = lookahead_m
        self.max_accel_mps2 = max_accel_mps2

    def describe(self) -> dict[str, Any]:
        """What the results record: the policy's kind and rate, and the controller with its parameters."""
        return {
            "policy_kind": "waypoints",
            "policy_rate_hz": self.rate_hz,
            "controller": {
                "name": "regulated_pure_pursuit",
                "lookahead_m": self.lookahead_m,
                "max_accel_mps2": self.max_accel_mps2,
            },
        }

    def reset(self, episode: Episode) -> None:
        """Reset the policy; forget the last plan."""
        self.robot = episode.params.robot
        self.dt = 1.0 / float(self.robot.control_hz)
        self.policy.reset(episode)
        self._path: np.ndarray | None = None
        self._next_query = -np.inf
        self._progress = 0.0
        self._v = 0.0

    def _replan(self, observation: dict[str, Any], pose: np.ndarray) -> None:
        local = _waypoints(self.policy.plan(observation), self.name)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        world = np.column_stack(
            [pose[0] + c * local[:, 0] - s * local[:, 1], pose[1] + s * local[:, 0] + c * local[:, 1]]
        )
        self._path = np.vstack([pose[:2], world])
        self._arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self._path, axis=0), axis=1))])
        self._progress = 0.0

    def _point_at(self, s: float) -> np.ndarray:
        return np.array([np.interp(s, self._arc, self._path[:, 0]), np.interp(s, self._arc, self._path[:, 1])])

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """Query the policy when its period has passed, then one pure-pursuit command."""
        state = observation["state"]
        pose = np.asarray(state["pose"], dtype=np.float64)
        t = float(np.asarray(state["t"]).reshape(-1)[0])
        if t >= self._next_query - 1e-9:
            self._replan(observation, pose)
            self._next_query = t + 1.0 / self.rate_hz
        total = float(self._arc[-1])
        # monotone projection: the closest point within the next 1 m of the polyline
        samples = np.linspace(self._progress, min(self._progress + 1.0, total), 21)
        points = np.column_stack([np.interp(samples, self._arc, self._path[:, k]) for k in (0, 1)])
        self._progress = float(samples[np.argmin(np.linalg.norm(points - pose[:2], axis=1))])
        remaining = total - self._progress
        target = self._point_at(self._progress + self.lookahead_m)
        rel = target - pose[:2]
        c, s = np.cos(pose[2]), np.sin(pose[2])
        x, y = c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1]
        max_w = float(np.deg2rad(self.robot.max_yaw_rate_deg_s))
        distance = float(np.hypot(x, y))
        bearing = float(wrap_angle(np.arctan2(y, x)))
        if distance < 1e-3 or remaining < 0.05 and distance < 0.05:
            v_goal, omega = 0.0, 0.0  # at the end of this plan: wait for the next one
        elif abs(bearing) > TURN_IN_PLACE_RAD:
            v_goal, omega = 0.0, float(np.clip(2.0 * bearing, -max_w, max_w))
        else:
            kappa = 2.0 * y / (distance * distance)
            v_goal = min(float(self.robot.max_speed_mps), max_w / max(abs(kappa), 1e-9), 1.5 * remaining)
            omega = float(np.clip(v_goal * kappa, -max_w, max_w))
        step = self.max_accel_mps2 * self.dt
        v = float(np.clip(v_goal, self._v - step, self._v + step))
        if v_goal > 0.0 and v > 0.0:
            omega *= v / v_goal  # stay on the same arc while the speed ramps
        self._v = v
        return v, omega
