"""Where pedestrians can stand and walk in a scene: legal centres, the main component, snap points."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon

from song.datasets.scenes import ScenePackage
from song.geometry.freespace import clearance_field, largest_component, walkable_cells
from song.geometry.grid import sample_mask
from song.geometry.gridpath import GridGraph, distances_from_many, grid_graph

SNAP_GAP_M = 0.15  # how far from an object's footprint a pedestrian stands (beyond its body radius)
COARSE_M = 0.2  # geodesic estimates for intents use a grid this coarse (±0.2 m is plenty for 2–40 m bounds)
STANDING_ROOM_M = 0.5  # extra clearance preferred around start/goal spots (a passer-by's body width)


@dataclass
class Walkable:
    """Legal pedestrian centres of a scene as the crowd's navmesh sees them, main component only.

    ``legal`` is :func:`song.geometry.freespace.walkable_cells` (free space eroded by the body radius,
    strips narrower than the navmesh keeps removed), so a goal the intents stage keeps is one the crowd
    can reach.
    """

    legal: np.ndarray  # (rows, cols) bool on the scene grid
    main: np.ndarray  # (rows, cols) bool: the largest connected part of ``legal``
    package: ScenePackage
    radius: float
    coarse_factor: int
    coarse: GridGraph
    clearance: np.ndarray  # (rows, cols) distance to the nearest obstacle, m
    _rows: dict = field(default_factory=dict, repr=False, compare=False)  # coarse start cell → distance row (cells)

    @property
    def area_m2(self) -> float:
        """Area of the main walkable component, m²."""
        return float(self.main.sum()) * self.package.occupancy.resolution**2

    def on_main(self, xy: np.ndarray) -> np.ndarray:
        """(...,) bool: points (..., 2) whose cell is on the main walkable component."""
        return sample_mask(self.main, self.package.occupancy.to_cell(xy))

    def _coarse_cell(self, point: np.ndarray) -> np.ndarray:
        rc = self.package.occupancy.to_cell(point) // self.coarse_factor
        if self.coarse.index[tuple(rc)] < 0:
            rc = self.coarse.cells[np.argmin(np.abs(self.coarse.cells - rc).sum(axis=1))]
        return rc

    def geodesics_from(self, starts: np.ndarray) -> tuple[np.ndarray, float]:
        """(S, n) coarse geodesic distances (m) from several points (S, 2).

        The starts not asked for before share one compiled call; a start cell's row is kept, since the
        stage asks again from the same spots (a Dijkstra is deterministic, so a kept row is the row).
        """
        res = self.package.occupancy.resolution * self.coarse_factor
        keys = [tuple(int(v) for v in self._coarse_cell(p)) for p in np.asarray(starts)]
        if not keys:
            return np.zeros((0, len(self.coarse.cells))), res
        new = list(dict.fromkeys(k for k in keys if k not in self._rows))
        if new:
            for key, row in zip(new, distances_from_many(self.coarse, np.array(new)), strict=True):
                self._rows[key] = row
        return np.stack([self._rows[k] for k in keys]) * res, res

    def geodesic(self, dist: np.ndarray, goal: np.ndarray) -> float:
        """The coarse geodesic distance (m) to ``goal`` from a row of :meth:`geodesics_from`; inf off the graph."""
        rc = self.package.occupancy.to_cell(goal) // self.coarse_factor
        if not sample_mask(self.coarse.index >= 0, rc):
            return float("inf")
        return float(dist[self.coarse.index[tuple(int(v) for v in rc)]])


def walkable(package: ScenePackage, radius: float, contour_error: float) -> Walkable:
    """Legal centres at ``radius`` and their largest 4-connected component; a coarse graph for geodesics.

    ``contour_error`` is the crowd navmesh's simplification error, m (it decides which strips survive).
    """
    grid = package.occupancy
    room = clearance_field(grid.free, grid.resolution)
    legal = walkable_cells(grid.free, grid.resolution, radius, contour_error, clearance=room)
    main = largest_component(legal)
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


MIN_WALKABLE_M2 = 2.0  # smaller than this, a crowd has nowhere to go (about four standing people)
MIN_SPOT_SEPARATION_M = 1.0  # two standing spots at least this far apart, connected


def usability_problems(package: ScenePackage, radius: float, contour_error: float) -> list[str]:
    """Every reason synthesis cannot use a (valid) scene package, one sentence each; empty when usable.

    Checks what the intents and crowd stages need: a walkable area (free space eroded by the body
    radius, strips narrower than the navmesh keeps removed) of at least ``MIN_WALKABLE_M2``, two
    connected standing spots ``MIN_SPOT_SEPARATION_M`` apart, and objects a pedestrian can stand next
    to (not buried in walls or cut off from the main walkable part).
    """
    walk = walkable(package, radius, contour_error)
    problems = []
    if walk.area_m2 < MIN_WALKABLE_M2:
        problems.append(
            f"walkable area for a {radius:g} m pedestrian is {walk.area_m2:.2f} m² (need ≥ {MIN_WALKABLE_M2:g} m²)"
        )
    cells = np.argwhere(walk.main)
    if len(cells):
        span = float(np.linalg.norm(np.ptp(cells, axis=0))) * package.occupancy.resolution
        if span < MIN_SPOT_SEPARATION_M:
            problems.append(f"no two connected standing spots {MIN_SPOT_SEPARATION_M:g} m apart (span {span:.2f} m)")
    objects = package.semantic_map.objects
    if not objects:
        problems.append("semantic_map.json: objects: none (pedestrians need objects to walk to)")
    stranded = [obj.id for obj in objects if not len(snap_points(walk, obj.footprint))]
    if objects and len(stranded) == len(objects):
        problems.append(f"no object can be reached on foot ({len(objects)} objects in walls or cut off)")
    elif stranded:
        shown = ", ".join(stranded[:5]) + (", …" if len(stranded) > 5 else "")
        problems.append(f"{len(stranded)} of {len(objects)} objects cannot be reached on foot: {shown}")
    return problems
