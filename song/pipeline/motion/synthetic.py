"""Synthetic planned trajectories for tests and benchmarks.

Straight, curves, stop-and-go, standing, turning on the spot: integrated from speed and yaw-rate
profiles at 30 FPS.
"""

from __future__ import annotations

import numpy as np

from song.config import DEFAULT_FPS as FPS
from song.geometry.rotations import wrap_angle
from song.pipeline.motion.types import Trajectory


def trajectory_from_profiles(
    ped_id: int, speed: np.ndarray, yaw_rate: np.ndarray, start: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> Trajectory:
    """Integrate per-frame speed (m/s) and yaw rate (rad/s) into a 30 FPS trajectory.

    Args:
        ped_id: id to give the trajectory.
        speed: ``(T,)`` m/s along the heading.
        yaw_rate: ``(T,)`` rad/s.
        start: ``(x, y, yaw)`` at frame 0.
    """
    speed = np.asarray(speed, dtype=np.float64)
    yaw_rate = np.asarray(yaw_rate, dtype=np.float64)
    n = len(speed)
    dt = 1.0 / FPS
    yaw = start[2] + np.concatenate([[0.0], np.cumsum(yaw_rate[:-1]) * dt])
    step = np.stack([np.cos(yaw), np.sin(yaw)], axis=-1) * speed[:, None] * dt
    xy = np.array(start[:2]) + np.concatenate([[[0.0, 0.0]], np.cumsum(step[:-1], axis=0)])
    frame = np.arange(n, dtype=np.int32)
    return Trajectory(ped_id=ped_id, t=frame / FPS, frame=frame, xy=xy, yaw=wrap_angle(yaw), speed=speed)


def _ramp(n: int, rise: int, level: float) -> np.ndarray:
    x = np.clip(np.arange(n) / max(rise, 1), 0.0, 1.0)
    return level * x * x * (3 - 2 * x)


def synthetic_trajectories(seconds: float = 12.0) -> dict[str, Trajectory]:
    """Named scenarios.

    Straight walks at 0.5/1.0/1.4 m/s, a curve, a slalom, stop-and-go, standing, turning on the spot,
    accelerate-and-stop.
    """
    n = int(seconds * FPS)
    t = np.arange(n) / FPS
    rise = int(1.0 * FPS)
    out: dict[str, Trajectory] = {}
    zero = np.zeros(n)
    for index, level in enumerate((0.5, 1.0, 1.4)):
        out[f"straight_{level:.1f}"] = trajectory_from_profiles(index, _ramp(n, rise, level), zero)
    out["curve"] = trajectory_from_profiles(10, _ramp(n, rise, 0.9), np.where(t > 3.0, 0.5, 0.0))
    out["slalom"] = trajectory_from_profiles(11, _ramp(n, rise, 0.8), 0.6 * np.sin(2 * np.pi * t / 4.0))
    stop_go = _ramp(n, rise, 0.8) * np.clip(np.abs(np.sin(np.pi * t / 6.0)) * 2.0, 0.0, 1.0)
    out["stop_and_go"] = trajectory_from_profiles(12, stop_go, zero)
    out["standing"] = trajectory_from_profiles(13, zero, zero, start=(1.0, 2.0, 0.7))
    turn = np.where((t > 2.0) & (t < 5.0), 1.0, 0.0)  # a 3 rad turn on the spot
    out["turn_on_spot"] = trajectory_from_profiles(14, zero, turn)
    walk_stop = _ramp(n, rise, 1.0) * np.where(t < seconds / 2, 1.0, np.clip(1.0 - (t - seconds / 2) / 1.0, 0.0, 1.0))
    out["walk_then_stop"] = trajectory_from_profiles(15, walk_stop, zero)
    return out


def steady_walk(speed: float, seconds: float = 12.0) -> Trajectory:
    """A straight walk that ramps up over 1 s, then holds ``speed`` m/s (for gait-cycle figures)."""
    n = int(seconds * FPS)
    return trajectory_from_profiles(0, _ramp(n, FPS, speed), np.zeros(n))
