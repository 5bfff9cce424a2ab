"""Free space eroded by a disc, and the one clearance convention every layer uses.

Clearance convention: the clearance of a free cell is the distance from its centre to the boundary of
the nearest non-free cell (or of the grid: the world ends at the image edge), in metres, taken as the
Euclidean distance between cell centres minus half a cell. It is exact along rows and columns and at
most 0.21 cell generous on diagonals; non-free cells have clearance 0.

A disc of radius r centred on a cell centre is legal when the cell's clearance is at least r
(:func:`erode`). Connectivity is 4-neighbour everywhere (:data:`CONNECTIVITY`): a diagonal-only
contact between two cells carries no disc, the grid A* does not cut corners, and the navmesh traced
from the cells keeps no point contacts. :func:`open_passages` removes strips narrower than the navmesh
keeps, so that grid reasoning (intents) agrees with the navmesh the crowd walks on.

Functions take arrays (grids, resolutions), never scene packages.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

CONNECTIVITY = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)  # 4-neighbour components


def clearance_field(free: np.ndarray, resolution: float) -> np.ndarray:
    """Per-cell clearance, m (see the module docstring); 0 on non-free cells.

    Args:
        free: (rows, cols) bool, True where the cell is free.
        resolution: metres per cell.

    Returns:
        (rows, cols) float64 distance from each cell centre to the nearest obstacle boundary, m.
    """
    edt = ndimage.distance_transform_edt(np.pad(np.asarray(free, dtype=bool), 1))[1:-1, 1:-1]
    return np.maximum(edt - 0.5, 0.0) * resolution


def erode(free: np.ndarray, resolution: float, radius: float) -> np.ndarray:
    """(rows, cols) bool: cells whose centre can hold a disc of ``radius`` (m) without touching an obstacle."""
    return clearance_field(free, resolution) >= radius


def open_passages(mask: np.ndarray, min_width_cells: int) -> np.ndarray:
    """``mask`` without strips narrower than ``min_width_cells`` (a morphological opening by a square).

    ``min_width_cells`` ≤ 1 returns the mask unchanged.
    """
    mask = np.asarray(mask, dtype=bool)
    if min_width_cells <= 1:
        return mask.copy()
    return ndimage.binary_opening(mask, structure=np.ones((min_width_cells, min_width_cells), dtype=bool))


def navmesh_min_width_cells(resolution: float, contour_error: float) -> int:
    """Narrowest strip (cells) that survives the navmesh build at ``contour_error``.

    The build traces rings ¼ cell inside the cells' edges and then offsets them ε/2 − ¼ cell further
    inward on both sides (:mod:`song.geometry.navmesh`), so a strip of w cells keeps
    (w − ½)·res − max(ε − ½·res, 0) of width, which is positive from w = ⌊ε / res⌋ + 1.
    """
    return max(1, int(np.floor(contour_error / resolution + 1e-9)) + 1)


def components(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """4-neighbour connected components: ``(labels (rows, cols) int32, count)``; 0 is background."""
    labels, count = ndimage.label(np.asarray(mask, dtype=bool), structure=CONNECTIVITY)
    return labels, int(count)


def largest_component(mask: np.ndarray) -> np.ndarray:
    """(rows, cols) bool: the largest 4-connected part of ``mask`` (all False when it is empty)."""
    labels, count = components(mask)
    if count == 0:
        return np.zeros_like(np.asarray(mask, dtype=bool))
    sizes = np.bincount(labels.ravel())[1:]
    return labels == int(np.argmax(sizes)) + 1


def walkable_cells(
    free: np.ndarray, resolution: float, radius: float, contour_error: float, clearance: np.ndarray | None = None
) -> np.ndarray:
    """Legal pedestrian centres as the crowd's navmesh sees them: eroded by ``radius``, narrow strips removed.

    ``clearance``: ``free``'s :func:`clearance_field`, when the caller has it already.
    """
    room = clearance_field(free, resolution) if clearance is None else clearance
    return open_passages(room >= radius, navmesh_min_width_cells(resolution, contour_error))
