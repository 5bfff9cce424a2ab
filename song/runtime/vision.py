"""What the robot camera sees: the release's scene Gaussians plus the pedestrians' LBS-posed avatars.

A :class:`SceneView` belongs to one evaluation process. Per episode it loads the scene's Gaussians
once (activated at load: exp of log-scales, sigmoid of logits; kept for the next episode of the same
scene) and prepares each pedestrian's avatar on first sight. Per step it poses only the avatars whose
root lies within the camera's range and field of view (plus a body's width of margin) -- positions
*and* rotations by LBS from their compact caches -- and renders them together with the scene
(:func:`song.render.render`). Pedestrians without an avatar cache are drawn as their collision body
proxy (grey 2 cm splats filling the proxy body), so a camera still sees every person. One render per
step serves every camera sensor of that resolution.

In a lit scene (its USD proxy carries the baker's probe grid, :mod:`song.datasets.scenes.lighting`)
each avatar is shaded by the light where it stands: its colours, read as albedos, are multiplied by
the probes' mean irradiance at its root (bilinear) and the scene's exposure, then tone-mapped as the
scene's surfels were; and it casts a soft contact shadow (one flat dark Gaussian on the floor under
it). An unlit scene shows the avatars' colours as they are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song import plugins
from song.datasets.avatars.asset import load_avatar
from song.datasets.avatars.cache import PosedAvatar, load_compact_cache
from song.datasets.bench.types import Episode, pedestrian_states, track_motion
from song.datasets.scenes.lighting import ProbeGrid, probe_irradiance
from song.datasets.scenes.materials import linear_to_srgb, srgb_to_linear
from song.datasets.scenes.ply import read_gaussian_ply
from song.errors import BenchmarkError
from song.geometry.rotations import wrap_angle
from song.render import Camera, GaussianSet, RenderOutput, render, render_views, robot_camera
from song.render.gaussians import SH_C0
from song.runtime.avatars import body_proxy_points
from song.runtime.robot import Pose

AVATAR_MARGIN_M = 1.0  # a posed avatar reaches this far from its root (arms, hair): used when culling
PROXY_SIGMA_M = 0.02  # splat size of a body proxy point
PROXY_GREY = 0.55  # colour of a body proxy
SCENE_CACHE = 2  # scenes kept activated per process
SHADOW_SIGMA_M, SHADOW_OPACITY = 0.22, 0.45  # the contact shadow under a lit avatar
_TONE_STEPS = 4096
# the sRGB transfer as a lookup table, straight to SH DC coefficients
_TONE_DC = ((linear_to_srgb(np.linspace(0.0, 1.0, _TONE_STEPS + 1)) - 0.5) / SH_C0).astype(np.float32)


def scene_gaussians(path: Path | None) -> GaussianSet:
    """A scene's Gaussian PLY (standard or SuperSplat compressed) activated; empty when there is none."""
    if path is None:
        return GaussianSet.empty()
    cloud = read_gaussian_ply(path)
    return GaussianSet.from_raw(
        cloud.means, cloud.quats, cloud.log_scales, cloud.opacity_logits, cloud.sh_dc, cloud.sh_rest
    )


def scene_probes(usd_path: Path | None) -> ProbeGrid | None:
    """The baked light's probe grid from a scene's USD proxy, or None (no proxy, an unlit scene)."""
    if usd_path is None:
        return None
    from song.datasets.scenes.usd import read_usd_lighting

    text = read_usd_lighting(usd_path)
    if text is None:
        return None
    try:
        return ProbeGrid.from_json(text)
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise BenchmarkError(f"{usd_path}: customLayerData.song_lighting: malformed probe grid ({exc})") from exc


def contact_shadows(roots: np.ndarray) -> GaussianSet:
    """One flat, dark, half-transparent Gaussian on the floor under each root (M, 2)."""
    m = len(roots)
    means = np.column_stack([roots, np.full(m, 0.004)]).astype(np.float32)
    quats = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (m, 1))
    scales = np.tile(np.array([SHADOW_SIGMA_M, SHADOW_SIGMA_M, 0.002], np.float32), (m, 1))
    sh = np.full((m, 1, 3), -0.5 / SH_C0, np.float32)
    return GaussianSet(means, quats, scales, np.full(m, SHADOW_OPACITY, np.float32), sh)


@dataclass
class _Avatar:
    """A pedestrian's avatar prepared for per-step posing (static attributes activated once)."""

    posed: PosedAvatar | None
    scales: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    proxy: np.ndarray | None = None  # (M, 3) canonical proxy points when there is no avatar cache
    lit: tuple | None = None  # (light factor, SH) of the last shading
    albedo: np.ndarray | None = None  # (N, 3) linear albedos read from the DC colours, made on first shading

    def shaded(self, factor: np.ndarray) -> np.ndarray:
        """SH coefficients with the DC colour lit by ``factor`` (RGB: irradiance / π · 2^EV), tone-mapped."""
        key = tuple(np.round(factor, 3))
        if self.lit is None or self.lit[0] != key:
            if self.albedo is None:
                dc = np.clip(0.5 + SH_C0 * self.sh[:, 0, :].astype(np.float64), 0.0, 1.0)
                self.albedo = (srgb_to_linear(dc) * _TONE_STEPS).astype(np.float32)
            index = np.minimum(self.albedo * np.asarray(key, np.float32), _TONE_STEPS).astype(np.int32)
            sh = self.sh.copy()
            sh[:, 0, :] = _TONE_DC[index]
            self.lit = (key, sh)
        return self.lit[1]


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
        self._probes: dict[Path | None, ProbeGrid | None] = {}
        self._scene: GaussianSet | None = None
        self._probe_grid: ProbeGrid | None = None
        self._episode: Episode | None = None
        self._avatars: dict[int, _Avatar] = {}
        self._last: tuple[tuple, RenderOutput] | None = None

    def share_scenes(self, other: SceneView) -> None:
        """Use ``other``'s cache of loaded scenes and probes (envs of one process hold each scene once)."""
        self._scenes, self._probes = other._scenes, other._probes

    def reset(self, episode: Episode) -> None:
        """Load (or reuse) the episode's scene Gaussians; forget the previous episode's avatars."""
        key = episode.gaussians_path
        if key not in self._scenes:
            if len(self._scenes) >= SCENE_CACHE:
                self._scenes.pop(next(iter(self._scenes)))
            self._scenes[key] = scene_gaussians(key)
        if episode.usd_path not in self._probes:
            if len(self._probes) >= SCENE_CACHE:
                self._probes.pop(next(iter(self._probes)))
            self._probes[episode.usd_path] = scene_probes(episode.usd_path)
        # this episode's own references: a cache shared with other envs may drop them while we render
        self._scene, self._probe_grid = self._scenes[key], self._probes[episode.usd_path]
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
        """The avatars of pedestrians ``indices`` posed at ``t`` (positions and rotations by LBS).

        In a lit scene they are shaded by the probes and each brings its contact shadow.
        """
        sets = []
        tracks = self._episode.pedestrians
        probes = self._probe_grid
        if probes is not None and indices:
            _, roots, _ = pedestrian_states([tracks[k] for k in indices], t)
            factors = probe_irradiance(probes, roots) / math.pi * 2.0**probes.exposure_ev
            sets.append(contact_shadows(roots))
        for j, k in enumerate(indices):
            avatar = self._avatar(k)
            if avatar.posed is not None:
                shown, shift = track_motion(tracks[k], t)  # (t, zeros) unless it is a reactive pedestrian
                means, quats = avatar.posed.pose_at(shown)
                if tracks[k].shift is not None:
                    means[:, :2] += shift
            else:
                _, xy, _ = pedestrian_states([tracks[k]], t)
                yaw = float(np.interp(t, tracks[k].t, np.unwrap(tracks[k].yaw)))
                c, s = math.cos(yaw), math.sin(yaw)
                pts = avatar.proxy
                means = np.column_stack(
                    [c * pts[:, 0] - s * pts[:, 1] + xy[0, 0], s * pts[:, 0] + c * pts[:, 1] + xy[0, 1], pts[:, 2]]
                )
                quats = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (len(pts), 1))
            sh = avatar.sh if probes is None else avatar.shaded(factors[j])
            sets.append(GaussianSet(means, quats, avatar.scales, avatar.opacities, sh))
        return sets

    def request(
        self, pose: Pose, t: float, width: int, height: int, command: tuple[float, float] = (0.0, 0.0)
    ) -> tuple[tuple, list[GaussianSet], Camera] | None:
        """What :meth:`render` would draw for this view, as ``(key, sets, camera)``; None when it is cached."""
        command = (float(command[0]), float(command[1]))
        key = (pose.x, pose.y, pose.yaw, t, width, height, command)
        if self._last is not None and self._last[0] == key:
            return None
        cam_cfg = self._episode.params.camera
        camera = robot_camera(
            pose.x, pose.y, pose.yaw, cam_cfg.height_m, cam_cfg.hfov_deg, width, height, cam_cfg.near_m, cam_cfg.far_m
        )
        people = self.posed_avatars(self.visible_pedestrians(pose, t, cam_cfg.far_m, cam_cfg.hfov_deg), t)
        return key, [self._scene, *people], camera

    def accept(self, key: tuple, frame: RenderOutput) -> RenderOutput:
        """The rendered ``frame`` of :meth:`request`'s view through the camera model; cached for ``key``."""
        if self._model is None:
            self._model = plugins.lookup("camera_model", self.camera_model)(self._episode.params)
        pose = Pose(key[0], key[1], key[2])
        out = self._model.apply(frame, CameraContext(int(self._episode.seed), float(key[3]), pose, key[6]))
        self._last = (key, out)
        return out

    def render(
        self, pose: Pose, t: float, width: int, height: int, command: tuple[float, float] = (0.0, 0.0)
    ) -> RenderOutput:
        """The robot camera's view at ``pose`` and scenario time ``t`` (cached for repeated calls).

        ``command`` is the robot's last (v, ω): a camera model may blur by the motion it causes.
        """
        job = self.request(pose, t, width, height, command)
        if job is None:
            return self._last[1]
        key, sets, camera = job
        return self.accept(key, render(sets, camera, self.backend))


def render_together(views: list[tuple[SceneView, Pose, float, int, int, tuple[float, float]]]) -> None:
    """Render the views of several :class:`SceneView` (the envs of a vector env) together.

    One renderer call per backend and size (:func:`song.render.render_views`); each scene view then
    answers :meth:`SceneView.render` for its view from its cache, with the frame it would have rendered
    alone.
    """
    groups: dict[tuple, list[tuple[SceneView, tuple, list[GaussianSet], Camera]]] = {}
    for scene_view, pose, t, width, height, command in views:
        job = scene_view.request(pose, t, width, height, command)
        if job is not None:
            groups.setdefault((scene_view.backend, width, height), []).append((scene_view, *job))
    for (backend, _, _), jobs in groups.items():
        frames = render_views([(sets, camera) for _, _, sets, camera in jobs], backend)
        for (scene_view, key, _, _), frame in zip(jobs, frames, strict=True):
            scene_view.accept(key, frame)
