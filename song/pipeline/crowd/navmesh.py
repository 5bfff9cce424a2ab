"""The crowd stage's navmesh: built from a scene's occupancy grid, stored as ``navmesh.npz``.

Legal centres are free space eroded by the agent radius (:func:`song.geometry.freespace.erode`, the
rule every stage uses, so intents' start and goal points lie on the mesh up to a snap of a few
millimetres). The mesh itself is built by
:func:`song.geometry.navmesh.build_navmesh`; its build parameters travel inside the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from song.datasets.limits import read_npz
from song.datasets.run.layout import NAVMESH_FILE
from song.datasets.scenes import ScenePackage
from song.errors import FormatError, StageError
from song.geometry.freespace import erode
from song.geometry.navmesh import Navmesh, NavmeshBuildError, build_navmesh, navmesh_arrays, navmesh_from_arrays
from song.util import write_npz_atomic


def legal_centres(package: ScenePackage, radius: float) -> np.ndarray:
    """(rows, cols) bool: cells where a pedestrian of ``radius`` (m) may stand (free space eroded)."""
    grid = package.occupancy
    return erode(grid.free, grid.resolution, radius)


def scene_navmesh(package: ScenePackage, radius: float, contour_error: float) -> Navmesh:
    """The navmesh of a scene's legal centres at ``radius`` (m), simplified within ``contour_error`` (m)."""
    grid = package.occupancy
    legal = legal_centres(package, radius)
    try:
        return build_navmesh(legal, grid.resolution, grid.origin, radius, contour_error)
    except NavmeshBuildError as exc:
        raise StageError(f"{package.root}: {exc}") from None


def save_navmesh(path: str | Path, mesh: Navmesh) -> None:
    """Write the mesh (and its build parameters) as an uncompressed npz with deterministic bytes."""
    write_npz_atomic(path, **navmesh_arrays(mesh))


def load_navmesh(path: str | Path) -> Navmesh:
    """Read ``navmesh.npz`` (a file, or the scene folder holding it)."""
    path = Path(path)
    if path.is_dir():
        path = path / NAVMESH_FILE
    arrays = read_npz(path)
    try:
        return navmesh_from_arrays(arrays)
    except (KeyError, ValueError) as exc:
        raise FormatError(path, "", f"cannot read the navmesh: {exc}") from exc
