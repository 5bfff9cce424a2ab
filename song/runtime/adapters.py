"""Adapters for published waypoint-predicting models: SONG observations in, robot-frame waypoints out.

Each model's conventions (input size, colour order, pixel scaling, depth units and range, context
length, goal kind, output convention, query rate) are data in ``adapter_profiles.toml``, read from their
public code (cited there). :class:`ModelAdapter` is a waypoint policy (:mod:`song.runtime.waypoints`)
that prepares exactly what a profile describes and decodes what the model returns. To run a real
model, subclass the adapter of its profile and implement :meth:`ModelAdapter.load_model`, returning a
callable that takes the prepared inputs (below) and returns the model's raw output::

    class MyNoMaD(NoMaDAdapter):
        def load_model(self):
            model = load_my_checkpoint("nomad.pth")      # your installed code and weights
            return lambda inputs: run_diffusion(model, inputs["context"], inputs["goal_image"])

    song eval --bench DIR --policy my_nomad.py:MyNoMaD --resolution 320x240

Prepared inputs, a dict of numpy arrays:

- ``context``: (T, H, W, 3) float32 colour frames, oldest first, at the profile's size, colour order
  and pixel scale (``imagenet``: mean/std normalised; ``uint8``: 0..255); for depth-only profiles absent;
- ``depth``: (T, H, W) float32 metres, clipped to the profile's range, invalid pixels
  ``depth_invalid``;
- ``goal``: (2,) float32, robot frame, m (point-goal profiles; clipped where the profile says);
- ``goal_image``: (H, W, 3) float32 with the same transform as ``context`` (image-goal profiles).

Frames enter the context at the profile's rate (its ``rate_hz``), the way the robots these models ran
on fed them; until the context is full the first frame is repeated.
"""

from __future__ import annotations

import tomllib
from collections import deque
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from song.errors import SongError

PROFILES_PATH = Path(__file__).with_name("adapter_profiles.toml")
IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)


@dataclass(frozen=True)
class AdapterProfile:
    """One model's conventions (the fields of ``adapter_profiles.toml``; see its comments)."""

    name: str
    title: str
    code: str
    sensors: tuple[str, ...]
    image_size: tuple[int, int]  # width, height
    colour_order: str
    pixel_scale: str
    depth_units: str
    context_frames: int
    goal: str
    output: str
    output_points: int
    rate_hz: float
    depth_range_m: tuple[float, float] = (0.0, float("inf"))
    depth_invalid: float = 0.0
    goal_clip_m: float | None = None
    waypoint_unit_m: float = 1.0


@cache
def profiles() -> dict[str, AdapterProfile]:
    """Every profile in ``adapter_profiles.toml`` by name."""
    data = tomllib.loads(PROFILES_PATH.read_text(encoding="utf-8"))
    out = {}
    for name, entry in data.items():
        entry = dict(entry)
        entry["sensors"] = tuple(entry["sensors"])
        entry["image_size"] = tuple(entry["image_size"])
        if "depth_range_m" in entry:
            entry["depth_range_m"] = tuple(entry["depth_range_m"])
        out[name] = AdapterProfile(name=name, **entry)
    return out


def resize(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` (H, W[, C]) resized to ``size`` (width, height): area averaging when shrinking, else linear.

    Depth is resized with nearest-neighbour sampling by :func:`prepare_depth` instead, so that an
    edge never invents a depth between the two surfaces.
    """
    import cv2

    h, w = image.shape[:2]
    method = cv2.INTER_AREA if size[0] < w and size[1] < h else cv2.INTER_LINEAR
    return cv2.resize(np.ascontiguousarray(image), size, interpolation=method)


def prepare_colour(rgb: np.ndarray, profile: AdapterProfile) -> np.ndarray:
    """A SONG RGB frame (H, W, 3) uint8 in the profile's size, colour order and pixel scale, float32."""
    image = resize(np.asarray(rgb, np.uint8), profile.image_size).astype(np.float32)
    if profile.colour_order == "BGR":
        image = image[..., ::-1]
    if profile.pixel_scale == "imagenet":
        image = (image / 255.0 - IMAGENET_MEAN) / IMAGENET_STD
    return np.ascontiguousarray(image, dtype=np.float32)


def prepare_depth(depth: np.ndarray, profile: AdapterProfile) -> np.ndarray:
    """A SONG depth frame (H, W) metres in the profile's size and range; invalid pixels ``depth_invalid``."""
    import cv2

    d = cv2.resize(np.asarray(depth, np.float32), profile.image_size, interpolation=cv2.INTER_NEAREST)
    low, high = profile.depth_range_m
    invalid = ~np.isfinite(d) | (d <= 0.0) | (d > high)
    d = np.clip(d, low, high)
    d[invalid] = profile.depth_invalid
    return d.astype(np.float32)


def decode(raw: Any, profile: AdapterProfile) -> np.ndarray:
    """The model's raw output → (K, 2) robot-frame waypoints, m, by the profile's output convention.

    Raises:
        SongError: an output whose shape does not match the profile.
    """
    out = np.asarray(raw, dtype=np.float64)
    columns = {"waypoints_xy": (2, 3), "keypoints_xyz": (3,), "normalized_waypoints": (4,), "normalized_deltas": (2,)}
    allowed = columns[profile.output]
    if out.ndim != 2 or out.shape[0] != profile.output_points or out.shape[1] not in allowed:
        raise SongError(
            f"{profile.name} adapter: the model returned shape {out.shape}, expected "
            f"({profile.output_points}, {' or '.join(map(str, allowed))}) for output '{profile.output}'"
        )
    if profile.output == "normalized_deltas":
        return np.cumsum(out[:, :2], axis=0) * profile.waypoint_unit_m
    if profile.output == "normalized_waypoints":
        return out[:, :2] * profile.waypoint_unit_m
    return out[:, :2]


class ModelAdapter:
    """A waypoint policy that feeds a model in its own conventions (the module docstring).

    Subclasses set ``profile_name`` and implement :meth:`load_model`.
    """

    profile_name = ""

    def __init__(self) -> None:
        self.profile = profiles()[self.profile_name]
        self.rate_hz = self.profile.rate_hz
        goal_sensors = ("goal_image",) if self.profile.goal == "image" else ()
        self.sensors = ("state", *self.profile.sensors, *goal_sensors)
        self.model = self.load_model()

    def load_model(self) -> Any:
        """Return ``model(inputs: dict) -> raw output`` for this profile; your installed model goes here."""
        raise SongError(
            f"{type(self).__name__}: no model. Subclass it and implement load_model() to return your installed "
            f"{self.profile.title} (see song.runtime.adapters)"
        )

    def reset(self, episode: Any) -> None:
        """Start an empty context."""
        self.colour: deque[np.ndarray] = deque(maxlen=self.profile.context_frames)
        self.depth: deque[np.ndarray] = deque(maxlen=self.profile.context_frames)

    def inputs(self, observation: dict[str, Any]) -> dict[str, np.ndarray]:
        """This query's prepared inputs (and the context updated with the current frame)."""
        profile = self.profile
        out: dict[str, np.ndarray] = {}
        if "rgb" in profile.sensors:
            self.colour.append(prepare_colour(observation["rgb"], profile))
            frames = list(self.colour)
            out["context"] = np.stack([frames[0]] * (profile.context_frames - len(frames)) + frames)
        if "depth" in profile.sensors:
            self.depth.append(prepare_depth(observation["depth"], profile))
            frames = list(self.depth)
            out["depth"] = np.stack([frames[0]] * (profile.context_frames - len(frames)) + frames)
        if profile.goal == "point":
            goal = np.asarray(observation["state"]["goal"], np.float32)
            if profile.goal_clip_m is not None:
                goal = np.clip(goal, -profile.goal_clip_m, profile.goal_clip_m)
            out["goal"] = goal
        else:
            out["goal_image"] = prepare_colour(observation["goal_image"]["rgb"], profile)
        return out

    def plan(self, observation: dict[str, Any]) -> np.ndarray:
        """Prepare the inputs, run the model, decode its waypoints."""
        return decode(self.model(self.inputs(observation)), self.profile)


class NavDPAdapter(ModelAdapter):
    """NavDP: RGB-D context of 8, point goal, 24 waypoints (profile ``navdp``)."""

    profile_name = "navdp"


class IPlannerAdapter(ModelAdapter):
    """iPlanner: one depth image, point goal, 5 keypoints (profile ``iplanner``)."""

    profile_name = "iplanner"


class ViNTAdapter(ModelAdapter):
    """ViNT: RGB context of 6, image goal, 5 normalized waypoints (profile ``vint``)."""

    profile_name = "vint"


class NoMaDAdapter(ModelAdapter):
    """NoMaD: RGB context of 4, image goal, 8 normalized deltas (profile ``nomad``)."""

    profile_name = "nomad"
