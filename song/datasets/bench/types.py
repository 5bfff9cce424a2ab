"""Typed episodes that a benchmark release hands to the runtime.

CONTRACT between ``song.datasets.bench`` (which builds these from Parquet + blobs) and
``song.runtime`` (which only reads them). Arrays are numpy; units are SI; world frame Z-up.

Pedestrian presence: a pedestrian exists for the whole scenario. Before its first trajectory sample
it stands at its first pose, after its last sample it stands at its last pose (people wait at the
object they start from and stay at the one they reach). This is the runtime's documented choice.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from song.config import CameraConfig, CrowdConfig, RobotConfig


@dataclass(frozen=True)
class RuntimeParams:
    """Everything the runtime needs, as recorded in the release's ``meta/info.json``.

    The release is the single source of these values; ``song eval`` and the Gymnasium env read them
    from the opened benchmark, and any override is explicit and recorded with the results.

    Attributes:
        robot: limits, control rate, collision settings, goal radius.
        camera: the robot camera (height, FOV, near/far, resolution).
        pedestrian_radius_m: pedestrian body radius (the crowd's agent radius), m.
        fps: pedestrian trajectory rate, frames/s.
    """

    robot: RobotConfig = field(default_factory=RobotConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    pedestrian_radius_m: float = field(default_factory=lambda: CrowdConfig().agent_radius_m)
    fps: int = field(default_factory=lambda: CrowdConfig().fps)

    def to_json(self) -> dict:
        """A JSON-able dict (written into evaluation results)."""
        return {
            "robot": self.robot.model_dump(mode="json"),
            "camera": self.camera.model_dump(mode="json"),
            "pedestrian_radius_m": self.pedestrian_radius_m,
            "fps": self.fps,
        }


@dataclass(frozen=True)
class StaticMap:
    """The static occupancy map of a scene.

    Attributes:
        cells: (rows, cols) uint8; 255 free, 0 occupied, 127 unknown (unknown is not traversable).
        resolution: metres per cell.
        origin: (x_min, y_min) of the lower-left corner, metres; mapping as in song.geometry.grid
    """

    cells: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def free(self) -> np.ndarray:
        """(rows, cols) bool."""
        return self.cells == 255


@dataclass(frozen=True)
class PedestrianTrack:
    """One pedestrian's planned root trajectory at 30 FPS.

    Attributes:
        ped_id: id within the scene.
        t: (T,) float64 scenario time, s (increasing, 1/fps apart).
        xy: (T, 2) float64 root position, m.
        yaw: (T,) float64 heading, rad, CCW from +x.
        shift, motion_t: None for a track replayed as released. For reactive pedestrians
            (:mod:`song.runtime.reactive`), whose ``xy`` is already moved off the recording: ``motion_t`` (T,)
            the time of the recorded full-body motion to show at each sample, and ``shift`` (T, 2) how far
            to move that pose (:func:`track_motion`).
    """

    ped_id: int
    t: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    shift: np.ndarray | None = None
    motion_t: np.ndarray | None = None


@dataclass(frozen=True)
class AvatarBinding:
    """Where a pedestrian's avatar and its skinning cache live (files inside the release's blobs).

    Attributes:
        ped_id: pedestrian id within the scene.
        avatar_id: identity id in the avatar pool.
        asset_path: avatar asset file (canonical Gaussians + skinning), read by ``song.datasets.avatars``.
        cache_path: compact LBS cache (root + joint rotations per frame), posed by ``song.geometry.lbs``.
    """

    ped_id: int
    avatar_id: str
    asset_path: Path | None
    cache_path: Path | None


@dataclass(frozen=True)
class Episode:
    """A point-goal social-navigation episode with everything the runtime needs.

    Attributes:
        episode_id: stable id.
        scene_id: scene package id.
        difficulty: "easy" | "medium" | "hard".
        mode: sampling mode ("co_directional", "counter_directional", "encounter", "random").
        seed: episode seed.
        start_xy: (2,) float64 m; start_yaw rad.
        goal_xy: (2,) float64 m; goal_radius m (success when closer).
        geodesic_distance: L*, smoothed A* length, m.
        optimal_time: T* = L* / 0.5 m/s, s.
        t0: scenario time at which the robot starts, s.
        path: (K, 2) float64 smoothed A* path, m.
        factors: the four grading factors, bins and score.
        static_map: the occupancy map.
        pedestrians: the scene's pedestrian tracks.
        avatars: avatar bindings, one per pedestrian that has one.
        params: the runtime parameters the episode is run with (the release's, unless overridden).
        gaussians_path: the scene's Gaussian PLY inside the release, or None when it has none.
        usd_path: the scene's USD proxy inside the release (its metadata carries the baked light's
            probe grid, which lights the avatars), or None.
        split: the split of the episode's scene ("train", "val", "test", …; "test" before schema 1.3).
        reference_ped_id: the pedestrian the sampling mode is about (co/counter-directional: the one
            whose walk the robot follows or meets; encounter: the walking one passed within 1 m); -1
            for random episodes and releases before schema 1.3.
        encounter_time: predicted scenario time of the robot's closest pass with that pedestrian at
            its nominal speed along ``path``, s (NaN when there is none).
    """

    episode_id: str
    scene_id: str
    difficulty: str
    mode: str
    seed: int
    start_xy: np.ndarray
    start_yaw: float
    goal_xy: np.ndarray
    goal_radius: float
    geodesic_distance: float
    optimal_time: float
    t0: float
    path: np.ndarray
    static_map: StaticMap
    pedestrians: list[PedestrianTrack] = field(default_factory=list)
    avatars: list[AvatarBinding] = field(default_factory=list)
    factors: dict[str, float] = field(default_factory=dict)
    params: RuntimeParams = field(default_factory=RuntimeParams)
    gaussians_path: Path | None = None
    usd_path: Path | None = None
    split: str = "test"
    reference_ped_id: int = -1
    encounter_time: float = float("nan")


def track_motion(track: PedestrianTrack, t: float) -> tuple[float, np.ndarray]:
    """At scenario time ``t``: the recorded motion's time to pose, and the (2,) shift to move that pose by.

    ``(t, zeros)`` for a replayed track; for a reactive one, ``motion_t`` and ``shift`` interpolated as
    the positions are.
    """
    if track.shift is None or track.motion_t is None:
        return t, np.zeros(2)
    times = track.t
    if t <= times[0] or len(times) == 1:
        return float(track.motion_t[0]), track.shift[0].copy()
    if t >= times[-1]:
        return float(track.motion_t[-1]), track.shift[-1].copy()
    k = int(np.searchsorted(times, t, side="right")) - 1
    w = (t - times[k]) / (times[k + 1] - times[k])
    shown = (1.0 - w) * track.motion_t[k] + w * track.motion_t[k + 1]
    return float(shown), (1.0 - w) * track.shift[k] + w * track.shift[k + 1]


def pedestrian_states(tracks: list[PedestrianTrack], t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pedestrian root states at scenario time ``t`` (linear interpolation between samples).

    Returns:
        ``(ids (P,) int64, xy (P, 2) float64 m, velocity (P, 2) float64 m/s)``; positions clamp to
        the first/last sample outside a track's time span (velocity 0 there).
    """
    n = len(tracks)
    ids = np.empty(n, dtype=np.int64)
    xy = np.zeros((n, 2))
    vel = np.zeros((n, 2))
    for i, track in enumerate(tracks):
        ids[i] = track.ped_id
        times = track.t
        if t <= times[0] or len(times) == 1:
            xy[i] = track.xy[0] if t <= times[0] else track.xy[-1]
            continue
        if t >= times[-1]:
            xy[i] = track.xy[-1]
            continue
        k = int(np.searchsorted(times, t, side="right")) - 1
        dt = times[k + 1] - times[k]
        w = (t - times[k]) / dt
        xy[i] = (1.0 - w) * track.xy[k] + w * track.xy[k + 1]
        vel[i] = (track.xy[k + 1] - track.xy[k]) / dt
    return ids, xy, vel
