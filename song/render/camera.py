"""Pinhole cameras with OpenCV axes (x right, y down, z forward), posed from a robot pose.

A robot at (x, y) facing yaw θ (CCW from +x, Z up) carries its camera ``height`` metres above the
floor, looking horizontally along its heading: the camera's z axis is (cos θ, sin θ, 0), x (right)
is (sin θ, −cos θ, 0), y (down) is (0, 0, −1). Intrinsics from the image size and the horizontal
field of view: fx = fy = W / (2·tan(hfov/2)), principal point at the image centre (W/2, H/2) with
pixel (row i, col j) centred at (j + ½, i + ½), as gsplat uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Camera:
    """One pinhole camera.

    Attributes:
        rotation: (3, 3) float64 camera-from-world rotation (rows: the camera's x, y, z axes in world).
        position: (3,) float64 camera centre in the world, m.
        fx: focal length along x, px. fy: along y, px.
        cx: principal point x, px. cy: principal point y, px.
        width: image width, px. height: image height, px.
        near: near plane, m (Gaussians whose centre is nearer are culled). far: far plane, m.
    """

    rotation: np.ndarray
    position: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    near: float = 0.01
    far: float = 100.0

    @property
    def translation(self) -> np.ndarray:
        """(3,) camera-from-world translation ``−R·c``."""
        return -self.rotation @ self.position

    @property
    def viewmat(self) -> np.ndarray:
        """(4, 4) float64 world-to-camera matrix (gsplat's ``viewmats``)."""
        out = np.eye(4)
        out[:3, :3] = self.rotation
        out[:3, 3] = self.translation
        return out

    @property
    def intrinsics(self) -> np.ndarray:
        """(3, 3) float64 K (gsplat's ``Ks``)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) in camera coordinates (x right, y down, z forward), m."""
        return np.asarray(points, dtype=np.float64) @ self.rotation.T + self.translation

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (..., 2) (u right, v down; pixel centres at +½) and depths z (...,) of world points."""
        cam = self.to_camera(points)
        z = cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx * cam[..., 0] / z + self.cx
            v = self.fy * cam[..., 1] / z + self.cy
        return np.stack([u, v], axis=-1), z

    def ray_directions(self) -> np.ndarray:
        """(H, W, 3) world directions through every pixel centre, scaled so their camera z is 1."""
        j, i = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        cam = np.stack([(j - self.cx) / self.fx, (i - self.cy) / self.fy, np.ones_like(j)], axis=-1)
        return cam @ self.rotation


def focal_from_hfov(width: int, hfov_deg: float) -> float:
    """Fx = W / (2·tan(hfov/2)), px."""
    return width / (2.0 * math.tan(math.radians(hfov_deg) / 2.0))


def robot_camera(
    x: float,
    y: float,
    yaw: float,
    height_m: float,
    hfov_deg: float,
    width: int,
    height: int,
    near: float = 0.01,
    far: float = 100.0,
) -> Camera:
    """The camera of a robot at (x, y, yaw) mounted ``height_m`` above the floor, looking along its heading."""
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = np.array([[s, -c, 0.0], [0.0, 0.0, -1.0], [c, s, 0.0]])
    f = focal_from_hfov(width, hfov_deg)
    return Camera(
        rotation, np.array([x, y, height_m]), f, f, width / 2.0, height / 2.0, int(width), int(height), near, far
    )


def look_at(
    eye: np.ndarray,
    target: np.ndarray,
    width: int,
    height: int,
    hfov_deg: float = 70.0,
    up: tuple[float, float, float] = (0.0, 0.0, 1.0),
    near: float = 0.01,
    far: float = 100.0,
) -> Camera:
    """A camera at ``eye`` looking at ``target`` (world points, m), image up along ``up``."""
    eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:  # looking along up: any right vector will do
        right = np.cross(forward, np.array([1.0, 0.0, 0.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    f = focal_from_hfov(width, hfov_deg)
    return Camera(
        np.stack([right, down, forward]), eye, f, f, width / 2.0, height / 2.0, int(width), int(height), near, far
    )


def robot_cameras(poses: np.ndarray, height_m: float, hfov_deg: float, width: int, height: int, **clip) -> list[Camera]:
    """A batch of robot cameras for poses (B, 3) [x, y, yaw]."""
    return [
        robot_camera(float(p[0]), float(p[1]), float(p[2]), height_m, hfov_deg, width, height, **clip) for p in poses
    ]
