"""``song viz scene``: occupancy, regions with names, objects with labels, navmesh overlay."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from song.datasets.scenes import ScenePackage, load_scene_package
from song.geometry.freespace import erode
from song.render.draw import Canvas, colour, label, map_canvas, write_png

AGENT_RADIUS_M = 0.25


def draw_scene(package: ScenePackage, agent_radius: float = AGENT_RADIUS_M, labels: bool = True) -> Canvas:
    """The scene's top-down map with the navigable area (legal pedestrian centres) tinted."""
    import cv2

    grid = package.occupancy
    canvas = map_canvas(grid.cells, grid.resolution, grid.origin)
    image = canvas.image
    legal = erode(grid.free, grid.resolution, agent_radius)  # the legal centres the navmesh is built on
    tint = cv2.resize(legal.astype(np.uint8), image.shape[1::-1], interpolation=cv2.INTER_NEAREST).astype(bool)
    image[tint] = (0.75 * image[tint] + 0.25 * np.array([120, 200, 255])).astype(np.uint8)
    smap = package.semantic_map
    for index, region in enumerate(smap.regions):
        pts = canvas.px(np.asarray(region.polygon))
        cv2.polylines(image, [pts], True, colour(index), 2, cv2.LINE_AA)
    for obj in smap.objects:
        pts = canvas.px(np.asarray(obj.footprint))
        cv2.fillPoly(image, [pts], (205, 170, 125))
        cv2.polylines(image, [pts], True, (120, 80, 40), 1, cv2.LINE_AA)
    if labels:
        from shapely.geometry import Polygon

        for index, region in enumerate(smap.regions):
            anchor = Polygon(region.polygon).representative_point()
            centre = canvas.px(np.array([anchor.x, anchor.y]))
            label(image, region.name or region.type, (int(centre[0]) - 30, int(centre[1])), colour(index), 0.5)
        for obj in smap.objects:
            centre = canvas.px(np.asarray(obj.footprint).mean(axis=0))
            label(image, obj.id, (int(centre[0]) - 20, int(centre[1]) + 4), (90, 50, 20), 0.35)
    return canvas


def render_scene(scene_dir: str | Path, out: str | Path) -> Path:
    """Write the scene picture as PNG."""
    return write_png(out, draw_scene(load_scene_package(scene_dir)).image)
