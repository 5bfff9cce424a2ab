"""Stand-ins for NavDP, iPlanner, ViNT and NoMaD: they check the inputs against their profile and return waypoints.

Each stand-in refuses (``ValueError`` naming what is wrong) inputs of the wrong size, dtype, context
length, colour scale or depth units, the way a real checkpoint fed the wrong tensors fails or silently
misbehaves. It returns raw output in its model's convention: point-goal models head for the goal,
image-goal models drive straight ahead.
"""

from __future__ import annotations

import numpy as np

from song.runtime.adapters import IPlannerAdapter, NavDPAdapter, NoMaDAdapter, ViNTAdapter, profiles


class StandInModel:
    """``model(inputs) -> raw output`` for one profile, strict about what it is given."""

    def __init__(self, name: str) -> None:
        self.profile = profiles()[name]
        self.calls = 0

    def _check_images(self, key: str, images: np.ndarray, channels: int | None) -> None:
        p = self.profile
        w, h = p.image_size
        shape = (p.context_frames, h, w) + ((channels,) if channels else ())
        if images.dtype != np.float32 or images.shape != shape:
            raise ValueError(f"{p.name}: {key} must be float32 {shape}, got {images.dtype} {images.shape}")

    def __call__(self, inputs: dict) -> np.ndarray:
        p = self.profile
        self.calls += 1
        if "rgb" in p.sensors:
            context = inputs["context"]
            self._check_images("context", context, 3)
            if p.pixel_scale == "imagenet" and not (context.min() >= -2.2 and context.max() <= 2.7):
                raise ValueError(
                    f"{p.name}: context is not ImageNet-normalised (range {context.min()}..{context.max()})"
                )
            if p.pixel_scale == "uint8" and not (context.min() >= 0 and context.max() <= 255):
                raise ValueError(f"{p.name}: context must hold 0..255 pixel values")
        if "depth" in p.sensors:
            depth = inputs["depth"]
            self._check_images("depth", depth, None)
            if depth.max() > p.depth_range_m[1]:
                raise ValueError(f"{p.name}: depth above {p.depth_range_m[1]} m: wrong units (millimetres?)")
        if p.goal == "point":
            goal = inputs["goal"]
            if goal.shape != (2,) or not np.isfinite(goal).all():
                raise ValueError(f"{p.name}: goal must be (2,) metres in the robot frame")
            step = goal / max(np.linalg.norm(goal), 1e-6) * min(np.linalg.norm(goal), 2.0) / p.output_points
        else:
            goal_image = inputs["goal_image"]
            self._check_images("goal_image", goal_image[None].repeat(p.context_frames, 0), 3)
            step = np.array([1.0, 0.0]) * (
                0.5 / p.output_points if p.output in ("waypoints_xy", "keypoints_xyz") else 1.0
            )
        k = np.arange(1, p.output_points + 1)[:, None]
        if p.output == "waypoints_xy":
            return k * step
        if p.output == "keypoints_xyz":
            return np.column_stack([k * step, np.zeros(p.output_points)])
        if p.output == "normalized_waypoints":
            return np.column_stack([k * step, np.ones(p.output_points), np.zeros(p.output_points)])
        return np.tile(step, (p.output_points, 1))  # normalized deltas: one unit step ahead each


class NavDPStandIn(NavDPAdapter):
    def load_model(self):
        return StandInModel("navdp")


class IPlannerStandIn(IPlannerAdapter):
    def load_model(self):
        return StandInModel("iplanner")


class ViNTStandIn(ViNTAdapter):
    def load_model(self):
        return StandInModel("vint")


class NoMaDStandIn(NoMaDAdapter):
    def load_model(self):
        return StandInModel("nomad")
