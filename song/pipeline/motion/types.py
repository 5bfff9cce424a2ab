"""Motion-stage data types: a planned root trajectory in, a skeletal motion out."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from scipy.ndimage import gaussian_filter1d

from song.config import DEFAULT_FPS
from song.datasets.run.layout import CROWD_FILE
from song.errors import InputError
from song.geometry.fk import forward_kinematics
from song.geometry.rotations import wrap_angle

MAX_TURN_RATE = 4.0  # rad/s: a body turns at most this fast (≈ 180° in 0.8 s); plans may flip yaw in one frame


@numba.njit(cache=True, nogil=True)
def _rate_limited(values: np.ndarray, steps: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """The forward and the backward rate-limited passes, averaged (the Python loop cost ~9 ms a walk)."""
    n = len(values)
    forward, backward = values.copy(), values.copy()
    for i in range(1, n):
        forward[i] = forward[i - 1] + min(max(values[i] - forward[i - 1], -steps[i - 1]), steps[i - 1])
    for i in range(n - 2, -1, -1):
        backward[i] = backward[i + 1] + min(max(values[i] - backward[i + 1], -steps[i]), steps[i])
    return 0.5 * (forward + backward)


def true_runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """Half-open ``(start, stop)`` frame ranges of the runs of True in ``flags`` (T,)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(flags).astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def held_rows(values: np.ndarray) -> np.ndarray:
    """``values`` (T, K) with nan rows replaced by the nearest earlier finite row (the first one before it)."""
    ok = np.isfinite(values[:, 0])
    if not ok.any():
        return values
    last = np.maximum.accumulate(np.where(ok, np.arange(len(ok)), -1))
    return values[np.where(last >= 0, last, np.argmax(ok))]


def min_jerk(x: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile ``10x³ - 15x⁴ + 6x⁵`` of progress ``x`` (clipped to 0-1)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)


def rate_limited(values: np.ndarray, max_step: float) -> np.ndarray:
    """``values`` (T,) changing by at most ``max_step`` per sample; a jump becomes a ramp centred on it."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    return _rate_limited(values, np.full(max(len(values) - 1, 0), float(max_step)))


def body_heading(yaw: np.ndarray, t: np.ndarray, max_rate: float = MAX_TURN_RATE) -> np.ndarray:
    """Unwrapped body heading ``(T,)`` radians that follows the planned yaw at a bounded turn rate.

    The rate limiter runs forwards and backwards and the two are averaged, so a yaw flip in the plan
    becomes a turn centred on it (the average of two rate-limited signals is rate-limited too).
    """
    target = np.unwrap(np.asarray(yaw, dtype=np.float64))
    if len(target) < 2:
        return target
    steps = max_rate * np.diff(np.asarray(t, dtype=np.float64))
    return _rate_limited(np.ascontiguousarray(target), np.ascontiguousarray(steps))


@dataclass(frozen=True)
class Trajectory:
    """One pedestrian's planned root track (a slice of ``crowd.parquet``).

    Attributes:
        ped_id: pedestrian id.
        t: ``(T,)`` float64 seconds, strictly increasing.
        frame: ``(T,)`` int32 frame numbers (``t = frame / fps``).
        xy: ``(T, 2)`` float64 world positions, metres.
        yaw: ``(T,)`` float64 heading, radians CCW from +x.
        speed: ``(T,)`` float64 planned speed, m/s.
        surface: ``(T, 2)`` float64 [horizontal distance to its edge m, height m] of a counter, desk
            or table the pedestrian rests its hands on at that frame, nan elsewhere; None: never
            (:mod:`song.pipeline.motion.postures`; generators may ignore it).
        shelf: ``(T, 2)`` float64 [horizontal distance to its front m, top height m] of a shelf the
            pedestrian browses at that frame, nan elsewhere; None: never (as ``surface``).
    """

    ped_id: int
    t: np.ndarray
    frame: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    surface: np.ndarray | None = None
    shelf: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.t)
        if n < 1 or self.xy.shape != (n, 2) or self.yaw.shape != (n,) or self.speed.shape != (n,):
            raise InputError(CROWD_FILE, f"ped_id={self.ped_id}", "inconsistent trajectory arrays")
        if n > 1 and not np.all(np.diff(self.t) > 0):
            raise InputError(CROWD_FILE, f"ped_id={self.ped_id}.t", "times must be strictly increasing")
        if not (np.all(np.isfinite(self.xy)) and np.all(np.isfinite(self.yaw))):
            raise InputError(CROWD_FILE, f"ped_id={self.ped_id}", "non-finite x, y or yaw")
        for name in ("surface", "shelf"):
            value = getattr(self, name)
            if value is not None and value.shape != (n, 2):
                raise InputError(CROWD_FILE, f"ped_id={self.ped_id}", f"{name} must be (T, 2)")

    @property
    def n_frames(self) -> int:
        """Number of samples."""
        return len(self.t)

    @property
    def fps(self) -> float:
        """Frame rate from the time stamps (30 when there is a single frame)."""
        if len(self.t) < 2:
            return float(DEFAULT_FPS)
        return float(round(1.0 / np.median(np.diff(self.t)), 6))


@dataclass
class Motion:
    """A pedestrian's full-body motion on the 24-joint skeleton (world frame, Z up, metres).

    Attributes:
        ped_id: pedestrian id.
        t: ``(T,)`` float64 seconds.
        frame: ``(T,)`` int32 frame numbers.
        height_m: body height, m.
        rest_joints: ``(24, 3)`` float64 rest T-pose of this body (body frame x fwd, y left, z up).
        local_quats: ``(T, 24, 4)`` float64 wxyz parent-local rotations relative to the rest pose; the
            root's includes the world heading.
        root_pos: ``(T, 3)`` float64 world pelvis positions, m.
        contacts: ``(T, 2)`` bool (left, right foot) or ``None`` before detection.
        info: provenance (generator, model, seed, prompt, style, fallback) and later quality figures.
    """

    ped_id: int
    t: np.ndarray
    frame: np.ndarray
    height_m: float
    rest_joints: np.ndarray
    local_quats: np.ndarray
    root_pos: np.ndarray
    contacts: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return len(self.t)

    def fk(self) -> tuple[np.ndarray, np.ndarray]:
        """World joints ``(T, 24, 3)`` and global rotations ``(T, 24, 3, 3)``."""
        return forward_kinematics(self.rest_joints, self.local_quats, self.root_pos)

    @property
    def joints(self) -> np.ndarray:
        """World joint positions ``(T, 24, 3)`` float64, metres."""
        return self.fk()[0]


def path_yaw(traj: Trajectory) -> np.ndarray:
    """The yaw ``(T,)`` a body walking the plan faces (the gait's heading and the alignment's reference).

    The direction of travel where the plan walks, its recorded yaw where it stands (blended by speed).
    The crowd's yaw is a smoothed velocity heading that trails the path by ~0.1–0.3 s; a centred
    derivative of the planned positions does not, and it knows the turn that is coming.
    """
    if len(traj.t) < 3:
        return np.asarray(traj.yaw, dtype=np.float64)
    vel = gaussian_filter1d(np.gradient(traj.xy, traj.t, axis=0), 2.0, axis=0, mode="nearest")
    speed = np.linalg.norm(vel, axis=1)
    direction = np.arctan2(vel[:, 1], vel[:, 0])
    weight = np.clip((speed - 0.1) / 0.3, 0.0, 1.0)
    return traj.yaw + weight * wrap_angle(direction - traj.yaw)
