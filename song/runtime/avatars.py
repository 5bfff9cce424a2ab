"""Avatar collision (paper "Implementation Details"): Gaussian centres inside the robot's volume.

The robot collision volume is a sphere of radius 0.2 m centred at body height 0.8 m (default), or a
vertical cylinder of that radius from the floor to twice that height (``collision_volume =
"cylinder"``). A collision is reported when the count of posed avatar Gaussian centres inside
exceeds η_col = 5; the raw count is returned too. Only avatars whose root is within reach of the
robot are posed (the rest cannot reach the volume).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from song.datasets.avatars.asset import load_avatar
from song.datasets.avatars.cache import PosedAvatar, load_compact_cache
from song.datasets.bench.types import PedestrianTrack, pedestrian_states, track_motion

AVATAR_REACH_M = 1.0  # horizontal root-to-fingertip reach of a 1.95 m adult in T-pose is ≈ 0.95 m


def count_inside_volume(
    points: np.ndarray, robot_xy: np.ndarray, radius: float, height: float, volume: str = "sphere"
) -> int:
    """Number of points (M, 3) inside the robot's collision volume at ``robot_xy``."""
    if len(points) == 0:
        return 0
    dx, dy, z = points[:, 0] - robot_xy[0], points[:, 1] - robot_xy[1], points[:, 2]
    horizontal = dx * dx + dy * dy  # per-column arithmetic: no (M, 2) temporaries or short-axis reductions
    if volume == "sphere":
        dz = z - height
        return int(np.count_nonzero(horizontal + dz * dz < radius**2))
    if volume == "cylinder":
        return int(np.count_nonzero((horizontal < radius**2) & (z >= 0.0) & (z <= 2 * height)))
    raise ValueError(f"unknown collision volume {volume!r}; expected 'sphere' or 'cylinder'")


@dataclass
class AvatarCollider:
    """Counts posed Gaussian centres of nearby avatars inside the robot volume at time ``t``.

    Args:
        tracks: the scene's pedestrian root tracks (to decide who is within reach).
        pose: ``pose(ped_index, t) -> (G, 3)`` posed Gaussian centres of that pedestrian's avatar.
    """

    tracks: list[PedestrianTrack]
    pose: Callable[[int, float], np.ndarray]
    radius: float = 0.2
    height: float = 0.8
    volume: str = "sphere"

    def count(self, t: float, robot_xy: np.ndarray) -> int:
        """Posed Gaussian centres of nearby avatars inside the robot volume at robot_xy, time t."""
        _, xy, _ = pedestrian_states(self.tracks, t)
        if len(xy) == 0:
            return 0
        near = np.flatnonzero(np.linalg.norm(xy - robot_xy, axis=1) < AVATAR_REACH_M + self.radius)
        return sum(
            count_inside_volume(self.pose(int(i), t), robot_xy, self.radius, self.height, self.volume) for i in near
        )


def body_proxy_points(
    spacing: float = 0.04, body_height: float = 1.7, half_width: float = 0.18, half_depth: float = 0.12
):
    """Canonical point centres filling a plain body of elliptical cross-section (x forward, feet at z = 0).

    Used to pose a stand-in avatar when a release carries no avatar caches: it moves and turns with
    the pedestrian's root, so collision counting still follows the η_col rule on real point counts.
    """
    axis = np.arange(-half_width, half_width + 1e-9, spacing)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    inside = (x / half_depth) ** 2 + (y / half_width) ** 2 <= 1.0
    layer = np.column_stack([x[inside], y[inside]])
    z = np.arange(spacing / 2, body_height, spacing)
    return np.column_stack([np.tile(layer, (len(z), 1)), np.repeat(z, len(layer))])


def proxy_poser(tracks: list[PedestrianTrack]) -> Callable[[int, float], np.ndarray]:
    """A pose function placing :func:`body_proxy_points` at each pedestrian's root and heading."""
    canonical = body_proxy_points()

    def pose(index: int, t: float) -> np.ndarray:
        track = tracks[index]
        _, xy, _ = pedestrian_states([track], t)
        yaw = float(np.interp(t, track.t, np.unwrap(track.yaw)))
        c, s = np.cos(yaw), np.sin(yaw)
        out = canonical.copy()
        out[:, 0] = c * canonical[:, 0] - s * canonical[:, 1] + xy[0, 0]
        out[:, 1] = s * canonical[:, 0] + c * canonical[:, 1] + xy[0, 1]
        return out

    return pose


def make_collider(episode) -> AvatarCollider:
    """The collider for an episode: posed Gaussian avatars when the release has caches, else body proxies.

    The robot volume (radius, centre height, shape) comes from ``episode.params.robot``.
    """
    robot = episode.params.robot
    pose = gaussian_poser(episode) if any(a.cache_path for a in episode.avatars) else None
    return AvatarCollider(
        episode.pedestrians,
        pose or proxy_poser(episode.pedestrians),
        radius=robot.radius_m,
        height=robot.collision_height_m,
        volume=robot.collision_volume,
    )


def gaussian_poser(episode) -> Callable[[int, float], np.ndarray] | None:
    """Pose each pedestrian's avatar Gaussians by LBS from its compact cache (body proxy where it has none).

    Assets and caches are read on a pedestrian's first query (most never come near the robot) and kept
    for the episode. Returns None when no pedestrian has an avatar cache.
    """
    bindings = {b.ped_id: b for b in episode.avatars if b.cache_path is not None and b.asset_path is not None}
    if not bindings:
        return None
    tracks = episode.pedestrians
    proxy = proxy_poser(tracks)
    posed: dict[int, PosedAvatar | None] = {}

    def pose(index: int, t: float) -> np.ndarray:
        if index not in posed:
            binding = bindings.get(tracks[index].ped_id)
            posed[index] = (
                PosedAvatar.load(load_avatar(binding.asset_path), load_compact_cache(binding.cache_path))
                if binding is not None
                else None
            )
        avatar = posed[index]
        if avatar is None:
            return proxy(index, t)
        if tracks[index].shift is None:
            return avatar.means_at(t)
        shown, shift = track_motion(tracks[index], t)  # a reactive pedestrian, off its recording
        means = avatar.means_at(shown)
        means[:, :2] += shift
        return means

    return pose
