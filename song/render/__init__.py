"""Gaussian-splat rendering of RGB-D views: cameras, activated Gaussian sets, backends.

A layer of its own: imports only :mod:`song.geometry` (and numpy/numba); the runtime and the pictures
use it.
"""

from song.render.camera import Camera, focal_from_hfov, look_at, robot_camera, robot_cameras
from song.render.gaussians import GaussianSet, concat
from song.render.render import RenderOutput, render, render_batch, render_views, resolve_backend

__all__ = [
    "Camera",
    "GaussianSet",
    "RenderOutput",
    "concat",
    "focal_from_hfov",
    "look_at",
    "render",
    "render_batch",
    "render_views",
    "resolve_backend",
    "robot_camera",
    "robot_cameras",
]
