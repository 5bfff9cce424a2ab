"""Unicycle robot (paper "Setup": v ≤ 0.5 m/s, |ω| ≤ 45°/s, 10 Hz)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from song.geometry.rotations import wrap_angle


@dataclass(frozen=True)
class Pose:
    """Planar pose: x, y in metres, yaw in rad (CCW from +x)."""

    x: float
    y: float
    yaw: float

    @property
    def xy(self) -> np.ndarray:
        """(2,) position, m."""
        return np.array([self.x, self.y])


def clamp_command(v: float, omega: float, max_speed: float, max_yaw_rate: float) -> tuple[float, float]:
    """Clip a command to the robot's limits; forward motion only (v ∈ [0, max_speed]); NaN → 0."""
    v = 0.0 if not np.isfinite(v) else float(np.clip(v, 0.0, max_speed))
    omega = 0.0 if not np.isfinite(omega) else float(np.clip(omega, -max_yaw_rate, max_yaw_rate))
    return v, omega


def integrate(pose: Pose, v: float, omega: float, dt: float) -> Pose:
    """Exact unicycle motion over ``dt`` with constant (v, ω) (an arc, or a line when ω ≈ 0)."""
    if abs(omega) < 1e-9:
        return Pose(pose.x + v * dt * np.cos(pose.yaw), pose.y + v * dt * np.sin(pose.yaw), pose.yaw)
    yaw = pose.yaw + omega * dt
    radius = v / omega
    x = pose.x + radius * (np.sin(yaw) - np.sin(pose.yaw))
    y = pose.y - radius * (np.cos(yaw) - np.cos(pose.yaw))
    return Pose(float(x), float(y), float(wrap_angle(yaw)))
