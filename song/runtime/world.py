"""The static world of an episode: clearance field, disc collisions and range casting on the grid."""

from __future__ import annotations

import numpy as np

from song.datasets.bench.types import StaticMap
from song.geometry.freespace import clearance_field


class StaticWorld:
    """Occupancy queries for the robot ("static collision: robot disc against the grid").

    ``clearance`` holds, per cell centre, the distance in metres to the nearest non-free cell's
    boundary (Euclidean distance transform minus half a cell); outside the grid counts as occupied.
    """

    def __init__(self, static_map: StaticMap) -> None:
        self.map = static_map
        self.clearance = clearance_field(static_map.free, static_map.resolution)  # the rule every stage uses
        self.rows = static_map.cells.shape[0]

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """Distance to the nearest obstacle, m, for (..., 2) points (0 off the grid)."""
        xy = np.asarray(xy, dtype=np.float64)
        res = self.map.resolution
        col = np.floor((xy[..., 0] - self.map.origin[0]) / res).astype(np.intp)
        row = self.rows - 1 - np.floor((xy[..., 1] - self.map.origin[1]) / res).astype(np.intp)
        inside = (row >= 0) & (row < self.rows) & (col >= 0) & (col < self.clearance.shape[1])
        if inside.all():
            return self.clearance[row, col]
        out = np.zeros(row.shape)
        out[inside] = self.clearance[row[inside], col[inside]]
        return out

    def collides(self, xy: np.ndarray, radius: float) -> np.ndarray:
        """True where a disc of ``radius`` at ``xy`` touches an obstacle."""
        return self.clearance_at(xy) < radius

    def cast(self, origin: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
        """Ranges along rays from ``origin`` (2,) at world ``angles`` (n,), capped at ``max_range``.

        Sphere tracing on the clearance field: each step advances by the clearance (at least a
        quarter cell), so no obstacle is skipped and few iterations are needed.
        """
        directions = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        dist = np.zeros(len(angles))
        min_step = 0.25 * self.map.resolution
        for _ in range(4 * int(max_range / self.map.resolution) + 8):
            clear = self.clearance_at(origin + directions * dist[:, None])
            done = (clear <= 0.0) | (dist >= max_range)
            if done.all():
                break
            dist = np.where(done, dist, dist + np.maximum(clear, min_step))  # every ray at once
        return np.minimum(dist, max_range)


def cast_circles(
    origin: np.ndarray, angles: np.ndarray, centres: np.ndarray, radius: float, max_range: float
) -> np.ndarray:
    """Ranges along rays to the nearest of several discs (pedestrian bodies), ``max_range`` if none.

    Args:
        origin: (2,) ray origin, m.
        angles: (n,) world angles, rad.
        centres: (P, 2) disc centres, m.
        radius: disc radius, m.
        max_range: longest range returned, m.
    """
    ranges = np.full(len(angles), max_range)
    if len(centres) == 0:
        return ranges
    d = np.stack([np.cos(angles), np.sin(angles)], axis=-1)  # (n, 2)
    rel = centres - origin  # (P, 2)
    b = d @ rel.T  # (n, P) projection of the centre on the ray
    c = (rel**2).sum(axis=1)[None, :] - radius**2
    disc = b**2 - c
    hit = disc >= 0
    t = b - np.sqrt(np.where(hit, disc, 0.0))
    t = np.where(hit & (t >= 0), t, np.where(hit & (c < 0), 0.0, np.inf))
    return np.minimum(ranges, t.min(axis=1))
