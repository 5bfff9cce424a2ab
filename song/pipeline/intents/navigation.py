"""Where pedestrians can stand and walk in a scene: legal centres, the main component, snap points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from shapely.geometry import Polygon

from song.datasets.scenes import ScenePackage
from song.geometry.gridpath import GridGraph, clearance, distances_from_many, grid_graph

SNAP_GAP_M = 0.15  # how far from an object's footprint a pedestrian stands (beyond its body radius)
COARSE_M = 0.2  # geodesic estimates for intents use a grid this coarse (±0.2 m is plenty for 2–40 m bounds)
STANDING_ROOM_M = 0.5  # extra clearance preferred around start/goal spots (a passer-by's body width)  # geodesic estimates for intents run on a grid of this cell size


@dataclass
class Walkable:
    """Legal pedestrian centres of a scene (free space eroded by the body radius), main component only."""

    legal: np.ndarray  # (rows, cols) bool on the scene grid
    main: np.ndarray  # (rows, cols) bool: the largest connected part of ``legal``
    package: ScenePackage
    radius: float
    coarse_factor: int
    coarse: GridGraph
    clearance: np.ndarray  # (rows, cols) distance to the nearest obstacle, m

    @property
    def area_m2(self) -> float:
        return float(self.main.sum()) * self.package.occupancy.resolution**2

    def on_main(self, xy: np.ndarray) -> np.ndarray:
        rc = self.package.occupancy.to_cell(xy)
        rows, cols = self.main.shape
        ok = (rc[..., 0] >= 0) & (rc[..., 0] < rows) & (rc[..., 1] >= 0) & (rc[..., 1] < cols)
        out = np.zeros(rc.shape[:-1], dtype=bool)
        out[ok] = self.main[rc[..., 0][ok], rc[..., 1][ok]]
        return out

    def _coarse_cell(self, point: np.ndarray) -> np.ndarray:
        rc = self.package.occupancy.to_cell(point) // self.coarse_factor
        if self.coarse.index[tuple(rc)] < 0:
            rc = self.coarse.cells[np.argmin(np.abs(self.coarse.cells - rc).sum(axis=1))]
        return rc

    def geodesic_from(self, start: np.ndarray) -> tuple[np.ndarray, float]:
        """Coarse geodesic distances (m) from ``start`` to every coarse node; and the metres per cell."""
        rows, res = self.geodesics_from(np.asarray(start)[None])
        return rows[0], res

    def geodesics_from(self, starts: np.ndarray) -> tuple[np.ndarray, float]:
        """(S, n) coarse geodesic distances (m) from several points (S, 2), one compiled call."""
        res = self.package.occupancy.resolution * self.coarse_factor
        cells = np.array([self._coarse_cell(p) for p in np.asarray(starts)]).reshape(-1, 2)
        return distances_from_many(self.coarse, cells) * res, res

    def geodesic(self, dist: np.ndarray, goal: np.ndarray) -> float:
        rc = tuple(int(v) for v in self.package.occupancy.to_cell(goal) // self.coarse_factor)
        rows, cols = self.coarse.index.shape
        if not (0 <= rc[0] < rows and 0 <= rc[1] < cols) or self.coarse.index[rc] < 0:
            return float("inf")
        return float(dist[self.coarse.index[rc]])


def walkable(package: ScenePackage, radius: float) -> Walkable:
    """Legal centres at ``radius`` and their largest 8-connected component; a coarse graph for geodesics."""
    grid = package.occupancy
    room = clearance(grid.free, grid.resolution)
    legal = room >= radius + 0.5 * grid.resolution
    labels, count = ndimage.label(legal, structure=np.ones((3, 3)))
    if count == 0:
        main = legal
    else:
        sizes = np.bincount(labels.ravel())[1:]
        main = labels == (int(np.argmax(sizes)) + 1)
    factor = max(1, int(round(COARSE_M / grid.resolution)))
    rows, cols = main.shape
    pad = (-rows % factor, -cols % factor)
    coarse = (
        np.pad(main, ((0, pad[0]), (0, pad[1]))).reshape((rows + pad[0]) // factor, factor, -1, factor).any(axis=(1, 3))
    )
    return Walkable(legal, main, package, radius, factor, grid_graph(coarse), room)


def snap_points(
    walk: Walkable,
    footprint: list[tuple[float, float]],
    region: list[tuple[float, float]] | None = None,
    step: float = 0.1,
) -> np.ndarray:
    """Candidate standing points around an object footprint, on the walkable main component.

    When the object's region polygon is given, points inside it are preferred, so a pedestrian
    stands on the object's side of a thin wall rather than in the next room.
    """
    ring = Polygon(footprint).buffer(walk.radius + SNAP_GAP_M, join_style=2).exterior
    n = max(8, int(ring.length / step))
    pts = np.array([ring.interpolate(i / n, normalized=True).coords[0] for i in range(n)])
    pts = pts[walk.on_main(pts)]
    if len(pts):  # prefer spots where a standing person leaves room for others to pass
        grid = walk.package.occupancy
        rc = grid.to_cell(pts)
        room = walk.clearance[rc[:, 0], rc[:, 1]] >= walk.radius + STANDING_ROOM_M
        if room.any():
            pts = pts[room]
    if region is not None and len(pts):
        from shapely import contains_xy

        inside = contains_xy(Polygon(region), pts[:, 0], pts[:, 1])
        if inside.any():
            pts = pts[inside]
    return pts
