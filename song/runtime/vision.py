"""What the robot camera sees: the release's scene Gaussians plus the pedestrians' LBS-posed avatars.

A :class:`SceneView` belongs to one evaluation process. Per episode it loads the scene's Gaussians
once (activated at load: exp of log-scales, sigmoid of logits; kept for the next episode of the same
scene) and prepares each pedestrian's avatar on first sight. Per step it poses only the avatars whose
root lies within the camera's range and field of view (plus a body's width of margin) -- positions
*and* rotations by LBS from their compact caches -- and renders them together with the scene
(:func:`song.render.render`). Pedestrians without an avatar cache are drawn as their collision body
proxy (grey 2 cm splats filling the proxy body), so a camera still sees every person. One render per
step serves every camera sensor of that resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song import plugins
from song.datasets.avatars.asset import load_avatar
from song.datasets.avatars.cache import PosedAvatar, load_compact_cache
from song.datasets.bench.types import Episode, pedestrian_states
from song.datasets.scenes.ply import read_gaussian_ply
from song.geometry.rotations import wrap_angle
from song.render import GaussianSet, RenderOutput, render, robot_camera
from song.render.gaussians import SH_C0
from song.runtime.avatars import body_proxy_points
from song.runtime.robot import Pose

AVATAR_MARGIN_M = 1.0  # a posed avatar reaches this far from its root (arms, hair): used when culling
PROXY_SIGMA_M = 0.02  # splat size of a body proxy point
PROXY_GREY = 0.55  # colour of a body proxy
SCENE_CACHE = 2  # scenes kept activated per process


def scene_gaussians(path: Path | None) -> GaussianSet:
    """A scene's Gaussian PLY (standard or SuperSplat compressed) activated; empty when there is none."""
    if path is None:
        return GaussianSet.empty()
    cloud = read_gaussian_ply(path)
    return GaussianSet.from_raw(
        cloud.means, cloud.quats, cloud.log_scales, cloud.opacity_logits, cloud.sh_dc, cloud.sh_rest
    )


@dataclass
class _Avatar:
    """A pedestrian's avatar prepared for per-step posing (static attributes activated once)."""

    posed: PosedAvatar | None
    scales: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    proxy: np.ndarray | None = None  # (M, 3) canonical proxy points when there is no avatar cache


def _prepare(asset_path: Path | None, cache_path: Path | None) -> _Avatar:
    if asset_path is None or cache_path is None:
        points = body_proxy_points()
        grey = np.full((len(points), 1, 3), (PROXY_GREY - 0.5) / SH_C0, np.float32)
        scales = np.full((len(points), 3), PROXY_SIGMA_M, np.float32)
        return _Avatar(None, scales, np.full(len(points), 0.95, np.float32), grey, points)
    posed = PosedAvatar.load(load_avatar(asset_path), load_compact_cache(cache_path))
    activated = GaussianSet.from_raw(
        posed.gaussians.means,
        posed.gaussians.quats,
        posed.gaussians.log_scales,
        posed.gaussians.opacity_logits,
        posed.gaussians.sh_dc,
        posed.gaussians.sh_rest,
    )
    return _Avatar(posed, activated.scales, activated.opacities, activated.sh)


@dataclass(frozen=True)
class CameraContext:
    """What a camera model may use besides the ideal image.

    The episode's seed, the step's time and pose, and the robot's last command (v m/s, ω rad/s): the
    motion during the exposure.
    """

    seed: int
    t: float
    pose: Pose
    command: tuple[float, float] = (0.0, 0.0)


class IdealCamera:
    """The ``ideal`` camera model: the renderer's image and depth as they are (the paper's protocol)."""

    name = "ideal"

    def __init__(self, params: object | None = None) -> None:
        self.params = params

    def apply(self, frame: RenderOutput, context: CameraContext) -> RenderOutput:
        """The frame unchanged."""
        return frame


plugins.add("camera_model", "ideal", IdealCamera)


class SceneView:
    """Renders robot camera views of an episode (see the module docstring).

    Args:
        backend: render backend: ``auto`` or a ``render_backend`` plugin (``numba``, ``gsplat``, ...).
        camera_model: a ``camera_model`` plugin, ``Model(runtime params)`` with
            ``apply(frame, CameraContext) -> RenderOutput``; ``ideal`` leaves the render as it is.
    """

    def __init__(self, backend: str = "auto", camera_model: str = "ideal") -> None:
        self.backend = backend
        self.camera_model = camera_model
        self._model: object | None = None
        self._scenes: dict[Path | None, GaussianSet] = {}
        self._episode: Episode | None = None
        self._avatars: dict[int, _Avatar] = {}
        self._last: tuple[tuple, RenderOutput] | None = None

    def reset(self, episode: Episode) -> None:
        """Load (or reuse) the episode's scene Gaussians; forget the previous episode's avatars."""
        key = episode.gaussians_path
        if key not in self._scenes:
            if len(self._scenes) >= SCENE_CACHE:
                self._scenes.pop(next(iter(self._scenes)))
            self._scenes[key] = scene_gaussians(key)
        self._episode = episode
        self._avatars = {}
        self._last = None

    def _avatar(self, index: int) -> _Avatar:
        if index not in self._avatars:
            track = self._episode.pedestrians[index]
            binding = next((b for b in self._episode.avatars if b.ped_id == track.ped_id), None)
            self._avatars[index] = _prepare(
                binding.asset_path if binding else None, binding.cache_path if binding else None
            )
        return self._avatars[index]

    def visible_pedestrians(self, pose: Pose, t: float, far: float, hfov_deg: float) -> list[int]:
        """Indices of the pedestrians whose body may appear in the camera at ``pose`` and time ``t``."""
        _, xy, _ = pedestrian_states(self._episode.pedestrians, t)
        out = []
        half = math.radians(hfov_deg) / 2
        for k, p in enumerate(xy):
            d = float(np.hypot(*(p - pose.xy)))
            if d > far + AVATAR_MARGIN_M:
                continue
            bearing = wrap_angle(math.atan2(p[1] - pose.y, p[0] - pose.x) - pose.yaw)
            if d <= AVATAR_MARGIN_M or abs(bearing) <= half + math.asin(min(1.0, AVATAR_MARGIN_M / d)):
                out.append(k)
        return out

    def posed_avatars(self, indices: list[int], t: float) -> list[GaussianSet]:
        """The avatars of pedestrians ``indices`` posed at ``t`` (positions and rotations by LBS)."""
        sets = []
        tracks = self._episode.pedestrians
        for k in indices:
            avatar = self._avatar(k)
            if avatar.posed is not None:
                means, quats = avatar.posed.pose_at(t)
            else:
                _, xy, _ = pedestrian_states([tracks[k]], t)
                yaw = float(np.interp(t, tracks[k].t, np.unwrap(tracks[k].yaw)))
                c, s = math.cos(yaw), math.sin(yaw)
                pts = avatar.proxy
                means = np.column_stack(
                    [c * pts[:, 0] - s * pts[:, 1] + xy[0, 0], s * pts[:, 0] + c * pts[:, 1] + xy[0, 1], pts[:, 2]]
                )
                quats = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (len(pts), 1))
            sets.append(GaussianSet(means, quats, avatar.scales, avatar.opacities, avatar.sh))
        return sets

    def render(
        self, pose: Pose, t: float, width: int, height: int, command: tuple[float, float] = (0.0, 0.0)
    ) -> RenderOutput:
        """The robot camera's view at ``pose`` and scenario time ``t`` (cached for repeated calls).

        ``command`` is the robot's last (v, ω): a camera model may blur by the motion it causes.
        """
        command = (float(command[0]), float(command[1]))
        key = (pose.x, pose.y, pose.yaw, t, width, height, command)
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        cam_cfg = self._episode.params.camera
        camera = robot_camera(
            pose.x, pose.y, pose.yaw, cam_cfg.height_m, cam_cfg.hfov_deg, width, height, cam_cfg.near_m, cam_cfg.far_m
        )
        people = self.posed_avatars(self.visible_pedestrians(pose, t, cam_cfg.far_m, cam_cfg.hfov_deg), t)
        out = render([self._scenes[self._episode.gaussians_path], *people], camera, self.backend)
        if self._model is None:
            self._model = plugins.lookup("camera_model", self.camera_model)(self._episode.params)
        out = self._model.apply(out, CameraContext(int(self._episode.seed), float(t), pose, command))
        self._last = (key, out)
        return out
