"""A robot's-eye picture of a scene's Gaussians (``song viz view``), from a given or a chosen pose."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from song.datasets.scenes import load_scene_package
from song.datasets.scenes.package import GAUSSIANS
from song.errors import SceneError
from song.geometry.freespace import clearance_field
from song.render import render, robot_camera
from song.render.draw import write_png
from song.runtime.vision import scene_gaussians

BACKGROUND = (0.02, 0.02, 0.03)
VIEW_RANGE_M = 9.0  # rays of the view search stop here


def _object_labels(package) -> np.ndarray:
    """(rows, cols) uint8: 1 + (object index mod 254) under each object's footprint, 0 elsewhere."""
    from song.datasets.scenes.raster import Rasterizer

    grid = package.occupancy
    x0, y0 = grid.origin
    raster = Rasterizer((x0, y0), (x0 + grid.shape[1] * grid.resolution, y0 + grid.shape[0] * grid.resolution),
                        grid.resolution, fill=0)  # fmt: skip
    for k, obj in enumerate(package.semantic_map.objects):
        raster.polygon(np.asarray(obj.footprint), 1 + k % 254)
    return raster.cells[: grid.shape[0], : grid.shape[1]]


def pick_view(
    scene_root: str | Path, hfov_deg: float, candidates: int = 64, seed: int = 0
) -> tuple[float, float, float]:
    """A pose (x, y, yaw) that sees much of the scene; deterministic.

    Rays are cast over the occupancy map across the field of view from free cells 0.5 m or more from
    any obstacle, at 16 headings. A pose scores by the distinct objects its rays stop on plus the mean
    free length of its rays (a view into a room, not at a wall 1 m away).
    """
    package = load_scene_package(scene_root)
    grid = package.occupancy
    clear = clearance_field(grid.free, grid.resolution)
    cells = np.argwhere(clear >= min(0.5, float(clear.max())))
    if not len(cells):
        raise SceneError(scene_root, "occupancy", "no free cell to stand in")
    rng = np.random.default_rng(seed)
    cells = cells[rng.choice(len(cells), min(candidates, len(cells)), replace=False)]
    labels = _object_labels(package)
    blocked = ~grid.free
    steps = np.arange(0.3, VIEW_RANGE_M, grid.resolution)
    offsets = np.linspace(-1, 1, 25) * math.radians(hfov_deg) / 2
    best, best_score = None, -np.inf
    for x, y in grid.to_world(cells):
        for yaw in np.arange(16) * math.pi / 8:
            angles = yaw + offsets
            pts = np.stack([x + np.cos(angles)[:, None] * steps, y + np.sin(angles)[:, None] * steps], axis=-1)
            rc = grid.to_cell(pts.reshape(-1, 2)).reshape(len(angles), len(steps), 2)
            inside = (rc[..., 0] >= 0) & (rc[..., 0] < grid.shape[0]) & (rc[..., 1] >= 0) & (rc[..., 1] < grid.shape[1])
            rc = np.clip(rc, 0, np.array(grid.shape) - 1)
            hit = blocked[rc[..., 0], rc[..., 1]] | ~inside
            first = np.where(hit.any(axis=1), hit.argmax(axis=1), len(steps) - 1)
            stop = rc[np.arange(len(angles)), first]
            seen = {int(v) for v in labels[stop[:, 0], stop[:, 1]] if v}
            score = len(seen) + float(steps[first].mean())
            if score > best_score:
                best, best_score = (float(x), float(y), float(yaw)), score
    return best


def render_view(
    scene_root: str | Path,
    out: str | Path,
    pose: tuple[float, float, float] | None = None,
    width: int = 960,
    height: int = 540,
    camera_height_m: float = 1.2,
    hfov_deg: float = 80.0,
) -> Path:
    """Render the scene's ``3dgs_compressed.ply`` from ``pose`` (default :func:`pick_view`) to a PNG."""
    root = Path(scene_root)
    if not (root / GAUSSIANS).is_file():
        raise SceneError(root / GAUSSIANS, "", "no Gaussian scene here (make one with `song scenes splat`)")
    x, y, yaw = pose if pose is not None else pick_view(root, hfov_deg)
    camera = robot_camera(x, y, yaw, camera_height_m, hfov_deg, width, height)
    out_image = render(scene_gaussians(root / GAUSSIANS), camera, background=BACKGROUND)
    return write_png(out, out_image.rgb)
