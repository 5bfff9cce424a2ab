"""What a policy sees each step (DESIGN §8), and the declared renderer interface."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from song.runtime.robot import Pose, wrap_angle
from song.runtime.world import StaticWorld, cast_circles

BODY_RADIUS_M = 0.25  # pedestrian body disc for the range scan (matches the crowd agent radius)


@dataclass(frozen=True)
class ScanConfig:
    """A ring of range rays against walls and pedestrian bodies."""

    n_rays: int = 72
    max_range_m: float = 5.0


@dataclass(frozen=True)
class Observation:
    """One step's observation.

    Attributes:
        t: scenario time, s.
        pose: robot pose (x, y, yaw) in the world (GPS + compass, as in PointNav).
        velocity: (2,) last command (v m/s, ω rad/s).
        goal: (2,) goal in the robot frame (x forward, y left), m.
        goal_polar: (2,) (distance m, bearing rad) of the goal.
        scan: (n,) ranges, m, at ``scan_angles`` (robot frame, CCW from forward).
        scan_angles: (n,) rad.
        pedestrians: (P, 4) privileged [x, y, vx, vy] world states, or None for non-privileged runs.
    """

    t: float
    pose: Pose
    velocity: np.ndarray
    goal: np.ndarray
    goal_polar: np.ndarray
    scan: np.ndarray
    scan_angles: np.ndarray
    pedestrians: np.ndarray | None = None


def scan_angles(config: ScanConfig) -> np.ndarray:
    """Ray angles in the robot frame, (n,) rad, starting straight ahead."""
    return np.linspace(-np.pi, np.pi, config.n_rays, endpoint=False) + np.pi


def observe(
    t: float,
    pose: Pose,
    velocity: np.ndarray,
    goal_xy: np.ndarray,
    world: StaticWorld,
    ped_xy: np.ndarray,
    ped_vel: np.ndarray,
    scan: ScanConfig,
    privileged: bool,
) -> Observation:
    """Build the observation for the robot at ``pose``."""
    rel = goal_xy - pose.xy
    c, s = np.cos(pose.yaw), np.sin(pose.yaw)
    goal = np.array([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1]])
    angles = wrap_angle(scan_angles(scan))
    world_angles = angles + pose.yaw
    ranges = np.minimum(
        world.cast(pose.xy, world_angles, scan.max_range_m),
        cast_circles(pose.xy, world_angles, ped_xy, BODY_RADIUS_M, scan.max_range_m),
    )
    return Observation(
        t=t,
        pose=pose,
        velocity=np.asarray(velocity, dtype=np.float64),
        goal=goal,
        goal_polar=np.array([np.hypot(*goal), np.arctan2(goal[1], goal[0])]),
        scan=ranges,
        scan_angles=angles,
        pedestrians=np.hstack([ped_xy, ped_vel]) if privileged else None,
    )


class Renderer(Protocol):
    """RGB-D rendering of the Gaussian scene + avatars from the robot camera (DESIGN §9 camera).

    Declared for a GPU splatting backend (e.g. gsplat); SONG ships no renderer and nothing here
    pretends to render. ``render`` returns (rgb (H, W, 3) uint8, depth (H, W) float32 metres).
    """

    def render(self, pose: Pose, t: float) -> tuple[np.ndarray, np.ndarray]: ...
