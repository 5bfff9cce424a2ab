"""Occupancy-grid coordinates: image rows are north-up.

Cell (row r, col c) of a ``rows``-row grid covers x = x_min + (c + ½)·res,
y = y_min + (rows − 1 − r + ½)·res. All functions are vectorised over points.
"""

from __future__ import annotations

import numpy as np


def cell_to_world(rc: np.ndarray, rows: int, resolution: float, origin: tuple[float, float]) -> np.ndarray:
    """Cell centres in metres.

    Args:
        rc: (..., 2) int or float array of (row, col) indices.
        rows: number of grid rows.
        resolution: metres per cell.
        origin: (x_min, y_min) of the grid's lower-left corner, metres.

    Returns:
        (..., 2) float64 array of (x, y), metres.
    """
    rc = np.asarray(rc, dtype=np.float64)
    x = origin[0] + (rc[..., 1] + 0.5) * resolution
    y = origin[1] + (rows - 1 - rc[..., 0] + 0.5) * resolution
    return np.stack([x, y], axis=-1)


def world_to_cell(xy: np.ndarray, rows: int, resolution: float, origin: tuple[float, float]) -> np.ndarray:
    """The (row, col) of the cell containing each point (may lie outside the grid).

    Args:
        xy: (..., 2) array of (x, y), metres.
        rows: number of grid rows.
        resolution: metres per cell.
        origin: (x_min, y_min) of the grid's lower-left corner, metres.

    Returns:
        (..., 2) int64 array of (row, col).
    """
    xy = np.asarray(xy, dtype=np.float64)
    col = np.floor((xy[..., 0] - origin[0]) / resolution).astype(np.int64)
    row = rows - 1 - np.floor((xy[..., 1] - origin[1]) / resolution).astype(np.int64)
    return np.stack([row, col], axis=-1)


def inside_grid(rc: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Boolean mask of (row, col) indices that lie inside a grid of ``shape``."""
    rc = np.asarray(rc)
    return (rc[..., 0] >= 0) & (rc[..., 0] < shape[0]) & (rc[..., 1] >= 0) & (rc[..., 1] < shape[1])


def sample_mask(mask: np.ndarray, rc: np.ndarray, outside: bool = False) -> np.ndarray:
    """Values of a boolean grid at (row, col) indices; ``outside`` for indices off the grid."""
    rc = np.asarray(rc)
    ok = inside_grid(rc, mask.shape)
    out = np.full(rc.shape[:-1], outside, dtype=bool)
    out[ok] = mask[rc[..., 0][ok], rc[..., 1][ok]]
    return out
