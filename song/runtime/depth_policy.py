"""``depth``: the benchmark's first vision baseline.

It sees only the depth image, the goal and its own velocity -- no map, no pedestrian states.

Each step (10 Hz):

1. the depth image is back-projected through the release's camera (pinhole, mount height, field of
   view) and the points in the robot's height band (10 cm above the floor up to 30 cm above the
   camera) become 2-D obstacle points in the robot frame, thinned to one per 5 cm cell;
2. points seen in the last second stay in a short memory, carried along by dead reckoning of the
   robot's own commanded velocity (the camera sees 70°, the robot turns), and are dropped where the
   camera looks again;
3. a fan of constant (v, ω) commands is rolled out for 2 s; commands that come closer than the robot
   radius plus a margin to any obstacle point are rejected, and the one whose rollout ends nearest the
   goal (with a small bonus for clearance) is taken; when none is safe, it turns on the spot toward
   the goal's side.

It avoids what it sees, people included, but predicts no motion (a reactive baseline, like a depth
camera on a real robot without tracking).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from song.datasets.bench.types import Episode
from song.render import focal_from_hfov

BAND_LOW_M = 0.10  # obstacle points from this height above the floor ...
BAND_ABOVE_CAMERA_M = 0.30  # ... up to this much above the camera
MAX_RANGE_M = 4.0  # farther points are not considered
CELL_M = 0.05  # obstacle points are thinned to one per cell of this size
MEMORY_S = 1.0  # how long an obstacle point outside the current view is remembered
HORIZON_S, ROLLOUT_DT = 2.0, 0.1
MARGIN_M = 0.08  # clearance kept beyond the robot radius
CLEARANCE_WEIGHT = 0.15  # bonus per metre of clearance (up to 1 m) along a rollout
PIXEL_STRIDE = 4  # back-project every 4th pixel in each direction


def depth_points(depth: np.ndarray, hfov_deg: float, camera_height: float, stride: int = PIXEL_STRIDE) -> np.ndarray:
    """Obstacle points (N, 2) in the robot frame (x forward, y left), m, from a depth image (H, W)."""
    height, width = depth.shape
    f = focal_from_hfov(width, hfov_deg)
    rows, cols = np.mgrid[stride // 2 : height : stride, stride // 2 : width : stride]
    z = depth[rows, cols].astype(np.float64)
    x_cam = (cols + 0.5 - width / 2) * z / f
    y_cam = (rows + 0.5 - height / 2) * z / f
    up = camera_height - y_cam
    keep = (z > 0) & (z < MAX_RANGE_M) & (up > BAND_LOW_M) & (up < camera_height + BAND_ABOVE_CAMERA_M)
    points = np.column_stack([z[keep], -x_cam[keep]])
    if len(points) == 0:
        return points
    cells = np.unique(np.floor(points / CELL_M).astype(np.int64), axis=0)
    return (cells + 0.5) * CELL_M


def _move(points: np.ndarray, v: float, omega: float, dt: float) -> np.ndarray:
    """Points (N, 2) of the previous robot frame expressed in the frame after moving (v, ω) for dt."""
    if abs(omega) < 1e-9:
        dx, dy, dyaw = v * dt, 0.0, 0.0
    else:
        dyaw = omega * dt
        dx, dy = v / omega * math.sin(dyaw), v / omega * (1 - math.cos(dyaw))
    c, s = math.cos(dyaw), math.sin(dyaw)
    rel = points - np.array([dx, dy])
    return np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])


class DepthPolicy:
    """Reactive obstacle avoidance on the depth image (see the module docstring)."""

    sensors = ("state", "depth")

    def reset(self, episode: Episode) -> None:
        """Read the robot and camera parameters; build the command fan; clear the memory."""
        params = episode.params
        self.robot = params.robot
        self.camera = params.camera
        self.dt = 1.0 / self.robot.control_hz
        max_w = math.radians(self.robot.max_yaw_rate_deg_s)
        v = np.linspace(0.0, self.robot.max_speed_mps, 6)
        w = np.linspace(-max_w, max_w, 11)
        self.commands = np.array([(a, b) for a in v for b in w])
        steps = int(round(HORIZON_S / ROLLOUT_DT))
        k = np.arange(1, steps + 1)[None, :] * ROLLOUT_DT
        vv, ww = self.commands[:, 0:1], self.commands[:, 1:2]
        safe_w = np.where(np.abs(ww) < 1e-9, 1.0, ww)
        self.rollouts = np.stack(  # (C, K, 2) in the robot frame at the start of the step
            [
                np.where(np.abs(ww) < 1e-9, vv * k, vv / safe_w * np.sin(ww * k)),
                np.where(np.abs(ww) < 1e-9, 0.0 * k, vv / safe_w * (1 - np.cos(ww * k))),
            ],
            axis=-1,
        )
        self.memory = np.zeros((0, 2))
        self.memory_age = np.zeros(0)
        self.last = (0.0, 0.0)

    def _obstacles(self, depth: np.ndarray) -> np.ndarray:
        seen = depth_points(depth, self.camera.hfov_deg, self.camera.height_m)
        if len(self.memory):  # carry the memory along, forget old points and points in view now
            self.memory = _move(self.memory, *self.last, self.dt)
            self.memory_age = self.memory_age + self.dt
            bearing = np.abs(np.arctan2(self.memory[:, 1], self.memory[:, 0]))
            keep = (self.memory_age <= MEMORY_S) & (bearing > math.radians(self.camera.hfov_deg) / 2)
            self.memory, self.memory_age = self.memory[keep], self.memory_age[keep]
        self.memory = np.vstack([self.memory, seen])
        self.memory_age = np.concatenate([self.memory_age, np.zeros(len(seen))])
        return self.memory

    def act(self, observation: dict[str, Any]) -> tuple[float, float]:
        """The safe command whose rollout ends nearest the goal (see the module docstring)."""
        goal = np.asarray(observation["state"]["goal"], dtype=np.float64)
        obstacles = self._obstacles(np.asarray(observation["depth"]))
        end_gap = np.linalg.norm(self.rollouts[:, -1] - goal, axis=1)
        mid_gap = np.linalg.norm(self.rollouts[:, self.rollouts.shape[1] // 4] - goal, axis=1)
        cost = end_gap + 0.3 * mid_gap
        if len(obstacles):
            from scipy.spatial import cKDTree

            gaps, _ = cKDTree(obstacles).query(self.rollouts.reshape(-1, 2), distance_upper_bound=1.0)
            d = np.minimum(gaps, 1.0).reshape(self.rollouts.shape[:2]).min(axis=1)  # clearance, capped at 1 m
            safe = d > self.robot.radius_m + MARGIN_M
            cost = cost - CLEARANCE_WEIGHT * np.minimum(d, 1.0)
        else:
            safe = np.ones(len(cost), dtype=bool)
        if safe.any():
            best = int(np.argmin(np.where(safe, cost, np.inf)))
            command = (float(self.commands[best, 0]), float(self.commands[best, 1]))
        else:  # boxed in: turn on the spot toward the goal's side
            max_w = math.radians(self.robot.max_yaw_rate_deg_s)
            command = (0.0, max_w if goal[1] >= 0 else -max_w)
        self.last = command
        return command


class DepthWaypoints:
    """``depth`` as a waypoint policy at the control rate: the chosen command's 2 s rollout as waypoints."""

    sensors = DepthPolicy.sensors
    rate_hz = 10.0

    def __init__(self) -> None:
        self.inner = DepthPolicy()

    def reset(self, episode: Episode) -> None:
        """Reset the depth policy."""
        self.inner.reset(episode)

    def plan(self, observation: dict[str, Any]) -> np.ndarray:
        """The rollout (robot frame) of the command ``depth`` picks; a point to the side when it turns on the spot."""
        inner = self.inner
        v, omega = inner.act(observation)
        if v <= 0.0:
            return np.array([[0.0, 0.3 if omega >= 0 else -0.3]])
        best = int(np.argmin(np.abs(inner.commands[:, 0] - v) + np.abs(inner.commands[:, 1] - omega)))
        return inner.rollouts[best]
