"""The crowd stage's navmesh: built from a scene's occupancy grid, stored as ``navmesh.npz``.

Legal centres are free cells whose centre is at least r + ½ cell from every occupied cell centre
(a scipy distance transform; the same rule as the intents stage's walkable grid, so intents' start and
goal points lie on the mesh up to a snap of a few millimetres). The mesh itself is built by
:func:`song.geometry.navmesh.build_navmesh`; its build parameters travel inside the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from song.datasets.scenes import ScenePackage
from song.errors import FormatError
from song.geometry.gridpath import clearance
from song.geometry.navmesh import Navmesh, build_navmesh, navmesh_arrays, navmesh_from_arrays, obstacle_rings
from song.pipeline.crowd.orca import ObstacleSet, build_obstacles
from song.util import write_npz_atomic

NAVMESH_FILE = "navmesh.npz"
WALL_MARGIN_M = 0.005  # ORCA walls lie this much beyond the agent radius from the mesh


def legal_centres(package: ScenePackage, radius: float) -> np.ndarray:
    """(rows, cols) bool: cells where a pedestrian of ``radius`` (m) may stand (free space eroded)."""
    grid = package.occupancy
    return clearance(grid.free, grid.resolution) >= radius + 0.5 * grid.resolution


def scene_navmesh(package: ScenePackage, radius: float, contour_error: float) -> Navmesh:
    """The navmesh of a scene's legal centres at ``radius`` (m), simplified within ``contour_error`` (m)."""
    grid = package.occupancy
    legal = legal_centres(package, radius)
    return build_navmesh(legal, grid.resolution, grid.origin, radius, contour_error)


def crowd_obstacles(mesh: Navmesh) -> ObstacleSet | None:
    """ORCA walls: the mesh grown back by its agent radius (+ a 5 mm margin), in RVO2 vertex order."""
    rings = obstacle_rings(mesh, mesh.params.agent_radius + WALL_MARGIN_M)
    return build_obstacles(rings) if rings else None


def save_navmesh(path: str | Path, mesh: Navmesh) -> None:
    """Write the mesh (and its build parameters) as an uncompressed npz with deterministic bytes."""
    write_npz_atomic(path, **navmesh_arrays(mesh))


def load_navmesh(scene_dir: str | Path) -> Navmesh:
    """Read ``RUN/scenes/<id>/navmesh.npz``."""
    path = Path(scene_dir) / NAVMESH_FILE
    try:
        with np.load(path) as data:
            return navmesh_from_arrays(data)
    except (OSError, KeyError, ValueError) as exc:
        raise FormatError(path, "", f"cannot read the navmesh: {exc}") from exc
