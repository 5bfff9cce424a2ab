"""Sensors: the composable parts of an observation ("Sensors").

An observation is a dict of named sensor outputs. Each sensor declares its Gymnasium space as a
:class:`Box` (or a dict of them) without importing Gymnasium, is reset once per episode, and reads
what it needs from the :class:`RobotView` of the current step. Sensors are chosen by name
(``song eval --sensors state,scan``; ``SongNavEnv(sensors=...)``); adding one is a :class:`Sensor`
subclass registered as a ``sensor`` plugin (``@register("sensor", "name")``, :mod:`song.plugins`).

Built in:
- ``state``: the robot's own state: ``pose`` (x, y, yaw; GPS + compass as in PointNav), ``velocity``
  (last command v, ω), ``goal`` (goal in the robot frame, x forward, y left), ``goal_polar`` (distance,
  bearing), ``t`` (scenario time).
- ``scan``: a ring of range rays against walls and pedestrian bodies (a 2-D lidar stand-in).
- ``pedestrians`` (privileged): every pedestrian's [x, y, vx, vy, present] in the world frame, padded
  to the release's largest scene.
- ``rgb``, ``depth``, ``rgbd``: the robot camera rendered from the scene's Gaussians and the posed
  avatars (:mod:`song.runtime.vision`): ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 metres
  (expected planar depth, 0 where nothing is seen), ``rgbd`` both. The camera (mount height, field of
  view, near/far) is the release's; the resolution is an option (default the recorded 960×540), and all
  camera sensors of a run share one render per step.
- ``goal_image``: an image goal, ``{"rgb", "depth"}`` rendered once per episode at the goal pose (the
  goal, facing along the last leg of the planned path, at the start time): the NoMaD protocol.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from typing_extensions import override

from song import plugins
from song.datasets.bench.types import Episode, RuntimeParams, pedestrian_states
from song.errors import SongError
from song.geometry.rotations import wrap_angle
from song.render import resolve_backend
from song.runtime import camera_models  # noqa: F401 - registers the d435i camera model
from song.runtime.robot import Pose
from song.runtime.vision import SceneView
from song.runtime.world import StaticWorld, cast_circles

GOAL_RANGE_M = 1000.0  # bound of the goal coordinates in the state space (scenes are far smaller)
MAX_TIME_S = 1.0e4  # bound of the scenario time in the state space


@dataclass(frozen=True)
class Box:
    """A Gymnasium ``Box`` declared as data: bounds (scalars or arrays), shape and dtype.

    Datasets (``song collect``) read their features from these declarations: ``names`` label the
    entries of a vector, ``unit`` says what its numbers measure, and ``image`` marks a camera image
    ((H, W) or (H, W, 3) pixels).
    """

    low: float | np.ndarray
    high: float | np.ndarray
    shape: tuple[int, ...]
    dtype: type = np.float64
    names: tuple[str, ...] | None = None
    unit: str = ""
    image: bool = False

    def contains(self, value: np.ndarray) -> bool:
        """True when ``value`` has the shape and dtype and lies within the bounds."""
        value = np.asarray(value)
        return (
            value.shape == self.shape
            and value.dtype == np.dtype(self.dtype)
            and bool(np.all(value >= self.low) and np.all(value <= self.high))
        )


Space = Box | dict[str, Box]


def to_gym_space(space: Space) -> Any:
    """The Gymnasium space of a declared space (imports Gymnasium)."""
    from gymnasium import spaces

    if isinstance(space, dict):
        return spaces.Dict({name: to_gym_space(sub) for name, sub in space.items()})
    low = np.broadcast_to(np.asarray(space.low, dtype=space.dtype), space.shape).copy()
    high = np.broadcast_to(np.asarray(space.high, dtype=space.dtype), space.shape).copy()
    return spaces.Box(low=low, high=high, shape=space.shape, dtype=space.dtype)


@dataclass
class RobotView:
    """What the sensors may read at one step. Pedestrian states are computed once, on first use.

    Attributes:
        t: scenario time, s. pose: the robot pose. command: (2,) last (v m/s, ω rad/s).
        episode: the episode (its static map, goal, tracks, avatars and runtime parameters).
        world: the episode's static world (clearance field, ray casting).
    """

    t: float
    pose: Pose
    command: np.ndarray
    episode: Episode
    world: StaticWorld

    @cached_property
    def pedestrians(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ids (P,), xy (P, 2), velocity (P, 2))`` at ``t``."""
        return pedestrian_states(self.episode.pedestrians, self.t)


class Sensor:
    """Base of every sensor: a name, a declared space, a per-episode reset and an observation per step."""

    name: str = ""
    privileged: bool = False  # sees what a real robot could not (other agents' true states)

    def __init__(self, params: RuntimeParams, **options: Any) -> None:
        self.params = params

    def space(self) -> Space:
        """The declared observation space."""
        raise NotImplementedError

    def reset(self, episode: Episode) -> None:
        """Called once before an episode's first observation."""

    def observe(self, view: RobotView) -> np.ndarray | dict[str, np.ndarray]:
        """The sensor's output at ``view``; it must lie in :meth:`space`."""
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        """Name and parameters, recorded with evaluation results."""
        return {"name": self.name, "privileged": self.privileged}


class StateSensor(Sensor):
    """The robot's pose, last command, and the goal in its own frame."""

    name = "state"

    @override
    def space(self) -> dict[str, Box]:
        robot = self.params.robot
        max_w = float(np.deg2rad(robot.max_yaw_rate_deg_s))
        big = GOAL_RANGE_M
        return {
            "pose": Box(np.array([-big, -big, -np.pi]), np.array([big, big, np.pi]), (3,), names=("x", "y", "yaw")),
            "velocity": Box(
                np.array([0.0, -max_w]), np.array([robot.max_speed_mps, max_w]), (2,), names=("v", "omega")
            ),
            "goal": Box(-big, big, (2,), names=("goal_x", "goal_y")),
            "goal_polar": Box(
                np.array([0.0, -np.pi]), np.array([2 * big, np.pi]), (2,), names=("goal_distance", "goal_bearing")
            ),
            "t": Box(0.0, MAX_TIME_S, (1,), names=("t",), unit="s"),
        }

    @override
    def observe(self, view: RobotView) -> dict[str, np.ndarray]:
        pose = view.pose
        rel = view.episode.goal_xy - pose.xy
        c, s = np.cos(pose.yaw), np.sin(pose.yaw)
        goal = np.clip([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1]], -GOAL_RANGE_M, GOAL_RANGE_M)
        xy = np.clip(pose.xy, -GOAL_RANGE_M, GOAL_RANGE_M)
        return {
            "pose": np.array([xy[0], xy[1], pose.yaw if -np.pi <= pose.yaw <= np.pi else wrap_angle(pose.yaw)]),
            "velocity": np.array(view.command, dtype=np.float64),
            "goal": goal,
            "goal_polar": np.array([np.hypot(*goal), np.arctan2(goal[1], goal[0])]),
            "t": np.array([min(view.t, MAX_TIME_S)]),
        }


class MapSensor(Sensor):
    """The static map around the robot: a ``size`` × ``size`` crop of the occupancy grid, north up.

    Cells hold the map's values (255 free, 0 occupied, 127 unknown); outside the map reads 0. Declaring
    this sensor is also what entitles a policy to the whole static map and the release's planned path
    in ``reset`` (a robot with a floor plan of the building); without it ``reset`` hands neither.
    """

    name = "map"

    def __init__(self, params: RuntimeParams, size: int = 64) -> None:
        super().__init__(params)
        if size < 1:
            raise SongError(f"map sensor: size must be ≥ 1 cell (got {size})")
        self.size = int(size)

    @override
    def space(self) -> Box:
        return Box(0, 255, (self.size, self.size), np.uint8)

    @override
    def observe(self, view: RobotView) -> np.ndarray:
        grid = view.episode.static_map
        rows, cols = grid.cells.shape
        col = int(np.floor((view.pose.x - grid.origin[0]) / grid.resolution))
        row = rows - 1 - int(np.floor((view.pose.y - grid.origin[1]) / grid.resolution))
        half = self.size // 2
        out = np.zeros((self.size, self.size), np.uint8)
        r0, c0 = row - half, col - half
        rs, cs = max(r0, 0), max(c0, 0)
        re, ce = min(r0 + self.size, rows), min(c0 + self.size, cols)
        if rs < re and cs < ce:
            out[rs - r0 : re - r0, cs - c0 : ce - c0] = grid.cells[rs:re, cs:ce]
        return out

    @override
    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "size": self.size}


class ScanSensor(Sensor):
    """``n_rays`` range rays (CCW from straight ahead) against walls and pedestrian body discs."""

    name = "scan"

    def __init__(self, params: RuntimeParams, n_rays: int = 72, max_range_m: float = 5.0) -> None:
        super().__init__(params)
        if n_rays < 1 or not max_range_m > 0:
            raise SongError(f"scan sensor: n_rays must be ≥ 1 and max_range_m > 0 (got {n_rays}, {max_range_m})")
        self.n_rays, self.max_range_m = int(n_rays), float(max_range_m)
        self.angles = wrap_angle(np.linspace(-np.pi, np.pi, self.n_rays, endpoint=False) + np.pi)

    @override
    def space(self) -> Box:
        return Box(0.0, self.max_range_m, (self.n_rays,), unit="m")

    @override
    def observe(self, view: RobotView) -> np.ndarray:
        _, xy, _ = view.pedestrians
        world_angles = self.angles + view.pose.yaw
        ranges = np.minimum(
            view.world.cast(view.pose.xy, world_angles, self.max_range_m),
            cast_circles(view.pose.xy, world_angles, xy, self.params.pedestrian_radius_m, self.max_range_m),
        )
        return np.clip(ranges, 0.0, self.max_range_m)

    @override
    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "n_rays": self.n_rays, "max_range_m": self.max_range_m}


class PedestrianSensor(Sensor):
    """Privileged: every pedestrian's world [x, y, vx, vy, present], rows padded with zeros to ``capacity``."""

    name = "pedestrians"
    privileged = True

    def __init__(self, params: RuntimeParams, capacity: int = 64) -> None:
        super().__init__(params)
        self.capacity = int(capacity)

    @override
    def space(self) -> Box:
        big = GOAL_RANGE_M
        low = np.tile(np.array([-big, -big, -big, -big, 0.0]), (self.capacity, 1))
        high = np.tile(np.array([big, big, big, big, 1.0]), (self.capacity, 1))
        return Box(low, high, (self.capacity, 5))

    @override
    def observe(self, view: RobotView) -> np.ndarray:
        _, xy, vel = view.pedestrians
        n = min(len(xy), self.capacity)
        out = np.zeros((self.capacity, 5))
        out[:n, :2] = np.clip(xy[:n], -GOAL_RANGE_M, GOAL_RANGE_M)
        out[:n, 2:4] = np.clip(vel[:n], -GOAL_RANGE_M, GOAL_RANGE_M)
        out[:n, 4] = 1.0
        return out

    @override
    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "capacity": self.capacity}


class CameraSensor(Sensor):
    """Base of the rendered camera sensors: a resolution and a shared :class:`SceneView`."""

    def __init__(
        self,
        params: RuntimeParams,
        width: int | None = None,
        height: int | None = None,
        backend: str = "auto",
        scene_view: SceneView | None = None,
    ) -> None:
        super().__init__(params)
        self.width = int(width or params.camera.width_px)
        self.height = int(height or params.camera.height_px)
        if self.width < 1 or self.height < 1:
            raise SongError(f"{self.name} sensor: resolution must be positive (got {self.width}x{self.height})")
        self.scene_view = scene_view or SceneView(backend)

    @override
    def reset(self, episode: Episode) -> None:
        self.scene_view.reset(episode)

    def frame(self, view: RobotView):
        """The rendered view at this step (one render shared by every camera sensor of the suite).

        Its arrays are read-only: every sensor and the policy see the same pixels.
        """
        out = self.scene_view.render(view.pose, view.t, self.width, self.height, tuple(view.command))
        for array in (out.rgb, out.depth, out.alpha):
            array.setflags(write=False)
        return out

    def _rgb_space(self) -> Box:
        return Box(0, 255, (self.height, self.width, 3), np.uint8, image=True)

    def _depth_space(self) -> Box:
        return Box(0.0, float(self.params.camera.far_m), (self.height, self.width), np.float32, unit="m", image=True)

    @override
    def describe(self) -> dict[str, Any]:
        camera = self.params.camera
        return {
            **super().describe(),
            "width": self.width,
            "height": self.height,
            "hfov_deg": camera.hfov_deg,
            "mount_height_m": camera.height_m,
            "backend": resolve_backend(self.scene_view.backend),
            "camera_model": self.scene_view.camera_model,
        }


class RgbSensor(CameraSensor):
    """The robot camera's colour image."""

    name = "rgb"

    @override
    def space(self) -> Box:
        return self._rgb_space()

    @override
    def observe(self, view: RobotView) -> np.ndarray:
        return self.frame(view).rgb


class DepthSensor(CameraSensor):
    """The robot camera's depth image: expected planar depth, m; 0 where nothing is seen."""

    name = "depth"

    @override
    def space(self) -> Box:
        return self._depth_space()

    @override
    def observe(self, view: RobotView) -> np.ndarray:
        return np.minimum(self.frame(view).depth, np.float32(self.params.camera.far_m))


class RgbdSensor(CameraSensor):
    """Colour and depth of one render."""

    name = "rgbd"

    @override
    def space(self) -> dict[str, Box]:
        return {"rgb": self._rgb_space(), "depth": self._depth_space()}

    @override
    def observe(self, view: RobotView) -> dict[str, np.ndarray]:
        out = self.frame(view)
        return {"rgb": out.rgb, "depth": np.minimum(out.depth, np.float32(self.params.camera.far_m))}


def goal_pose(episode: Episode) -> Pose:
    """Where an image goal is taken: the goal, facing along the last leg of the episode's path."""
    path = np.asarray(episode.path, dtype=np.float64).reshape(-1, 2)
    points = np.vstack([episode.start_xy, path, episode.goal_xy])
    legs = np.diff(points, axis=0)
    moving = legs[np.linalg.norm(legs, axis=1) > 1e-6]
    yaw = float(np.arctan2(moving[-1, 1], moving[-1, 0])) if len(moving) else float(episode.start_yaw)
    return Pose(float(episode.goal_xy[0]), float(episode.goal_xy[1]), yaw)


class GoalImageSensor(CameraSensor):
    """An image goal (the paper's NoMaD protocol): colour and depth rendered at the goal pose.

    The camera stands at the goal facing along the last leg of the planned path (:func:`goal_pose`), at
    the episode's start time ``t0`` (the pedestrians where they are when the episode begins). Rendered
    once per episode at ``reset`` and returned unchanged every step.
    """

    name = "goal_image"

    @override
    def space(self) -> dict[str, Box]:
        return {"rgb": self._rgb_space(), "depth": self._depth_space()}

    @override
    def reset(self, episode: Episode) -> None:
        super().reset(episode)
        out = self.scene_view.render(goal_pose(episode), float(episode.t0), self.width, self.height)
        depth = np.minimum(out.depth, np.float32(self.params.camera.far_m))
        self._goal = {"rgb": out.rgb.copy(), "depth": depth.copy()}
        for array in self._goal.values():
            array.setflags(write=False)

    @override
    def observe(self, view: RobotView) -> dict[str, np.ndarray]:
        return self._goal


CAMERA_SENSORS = ("rgb", "depth", "rgbd", "goal_image")
for _sensor in (StateSensor, ScanSensor, PedestrianSensor, MapSensor, RgbSensor, DepthSensor, RgbdSensor,
                GoalImageSensor):  # fmt: skip
    plugins.add("sensor", _sensor.name, _sensor)


def register_sensor(name: str, factory: Callable[..., Sensor]) -> None:
    """Add a sensor type (``factory(params, **options) -> Sensor``) under ``name`` (a ``sensor`` plugin)."""
    plugins.add("sensor", name, factory)


def parse_sensor_names(text: str | Iterable[str]) -> tuple[str, ...]:
    """``"state,scan"`` (or a list) → validated, de-duplicated names in the given order."""
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    for name in names:
        plugins.lookup("sensor", name)  # refuses an unknown name, listing the known ones
    return tuple(dict.fromkeys(names))


@dataclass
class SensorSuite:
    """The sensors of a run, built once for the release's parameters."""

    sensors: dict[str, Sensor] = field(default_factory=dict)

    @classmethod
    def build(
        cls,
        names: Iterable[str],
        params: RuntimeParams,
        max_pedestrians: int = 64,
        options: dict[str, dict] | None = None,
    ) -> SensorSuite:
        """Sensors by name for ``params``.

        Args:
            names: sensor names (``sensor`` plugins, :mod:`song.plugins`).
            params: the runtime parameters (the release's, or explicit overrides).
            max_pedestrians: rows of the ``pedestrians`` sensor (the release's largest scene).
            options: per-sensor keyword options, e.g. ``{"scan": {"n_rays": 180}}``; ``"camera"`` holds the
                options every camera sensor shares: ``width``, ``height``, ``backend``, ``model`` (a
                ``camera_model`` plugin, default ``ideal``).
        """
        options = {name: dict(values) for name, values in (options or {}).items()}
        options.setdefault("pedestrians", {}).setdefault("capacity", max_pedestrians)
        camera = options.pop("camera", {})  # width, height, backend, model: shared by every camera sensor
        shared = SceneView(camera.get("backend", "auto"), camera.get("model") or params.camera.model)
        for name in CAMERA_SENSORS:
            options.setdefault(name, {}).update({**camera, "scene_view": shared})
            options[name].pop("backend", None)
            options[name].pop("model", None)
        out = {}
        for name in parse_sensor_names(names):
            out[name] = plugins.lookup("sensor", name)(params, **options.get(name, {}))
        return cls(out)

    @property
    def names(self) -> tuple[str, ...]:
        """The sensor names, in order."""
        return tuple(self.sensors)

    @property
    def privileged(self) -> bool:
        """True when any sensor is privileged."""
        return any(s.privileged for s in self.sensors.values())

    def space(self) -> dict[str, Space]:
        """The observation space: one entry per sensor."""
        return {name: sensor.space() for name, sensor in self.sensors.items()}

    def camera_views(self) -> list[tuple[SceneView, int, int]]:
        """The distinct (scene view, width, height) its camera sensors render (one per size)."""
        out = {(id(s.scene_view), s.width, s.height): (s.scene_view, s.width, s.height)
               for s in self.sensors.values() if isinstance(s, CameraSensor)}  # fmt: skip
        return list(out.values())

    def reset(self, episode: Episode) -> None:
        """Reset every sensor for ``episode``."""
        for sensor in self.sensors.values():
            sensor.reset(episode)

    def observe(self, view: RobotView) -> dict[str, Any]:
        """The observation dict at ``view``."""
        return {name: sensor.observe(view) for name, sensor in self.sensors.items()}

    def describe(self) -> list[dict[str, Any]]:
        """Every sensor's name and parameters."""
        return [sensor.describe() for sensor in self.sensors.values()]


def space_contains(space: Space, value: Any) -> bool:
    """True when ``value`` lies in a declared space (dicts recursively)."""
    if isinstance(space, dict):
        return (
            isinstance(value, dict)
            and set(value) == set(space)
            and all(space_contains(space[k], value[k]) for k in space)
        )
    return space.contains(value)
