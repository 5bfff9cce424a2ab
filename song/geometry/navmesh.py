"""Navigation mesh over a grid of legal agent centres: Recast's build, Detour's queries, exact paths.

Build (Recast semantics; the caller erodes free space by the agent radius, so every point of the mesh
is a legal centre):

1. Contours of the legal cells are traced with OpenCV on a 2× upsampled mask (so one-cell-wide
   passages keep a non-zero width); the traced rings run ¼ cell inside the cells' outer edges.
2. Simplification with error ε (``contour_error``): Douglas–Peucker with tolerance ε/2, then an inward
   offset of ε/2 − ¼ cell (mitred; none when ε ≤ ½ cell). Douglas–Peucker keeps every point within
   ε/2 of the traced ring, so the offset result lies inside the legal cells (the traced ring has ¼
   cell to spare): the mesh never leaves them, and its boundary is at most ε + ¼ cell inside them.
3. Triangulation with mapbox-earcut (chosen over shapely's constrained Delaunay: it returns vertex
   indices directly, handles holes, and is several times faster; triangle shape does not matter
   here because paths come from the funnel and the visibility graph, not from triangle centres).
4. Triangle adjacency (shared vertex pairs, after splitting edges at T-junctions: earcut leaves
   zero-area triangles where ring vertices are collinear, and dropping them would cut the mesh along
   an edge), connected components, reflex vertices of the boundary and the reduced visibility graph
   between them (bitangent, unobstructed pairs).

Queries (Detour's statuses, exact lengths): nearest-point snapping (a point off the mesh moves to the
nearest boundary point, then ``NUDGE_M`` into its triangle), then the true shortest path within
the mesh by A* over the reduced visibility graph (shortest paths in a polygonal domain bend only at
reflex vertices, on bitangent edges), compiled with numba (:mod:`song.geometry._navmesh_kernel`; the
numpy implementation it replaced is the reference twin in :mod:`song.geometry._navmesh_reference`).
Detour's own query (A* over triangles with edge-midpoint costs, then the funnel) is kept as
:meth:`Navmesh.corridor` and :meth:`Navmesh.funnel_path`; it can go round the wrong side of an
obstacle. :meth:`Navmesh.distances` answers one source and many goals with one search. Nothing raises
on a bad query: a :class:`PathResult` carries ``ok`` / ``partial`` / ``unreachable`` / ``off_mesh``
and a reason.

Boundary tolerance: one constant, ``TOUCH_EPS`` (1e-12 m², a cross product: about 1e-12 m off a 1 m
wall), decides when a point counts as on a wall's line. A line of sight whose own end lies on a wall
is not blocked by that wall (its ends are mesh points, so leaving the mesh there would mean crossing
another wall), which keeps goals snapped onto, or a hair inside, a boundary edge reachable.
"""

from __future__ import annotations

import heapq
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from song.geometry import _navmesh_kernel as _k
from song.geometry._navmesh_kernel import TOUCH_EPS

NAVMESH_FORMAT = 1
BUCKET_M = 0.5  # cell size of the spatial hash used for wall and triangle look-ups
OFFSET_SLACK_M = 1e-4  # added to the inward offset: a strip exactly twice the offset wide must vanish, not
# collapse into a zero-width bridge between two parts (at ε = 1 cell, one-cell strips are that wide)
CARVINGS_KEPT = 256  # carvings a mesh remembers (:func:`carve_discs`; ~0.2 MB each with their query arrays)
T_JUNCTION_M = 1e-9  # a vertex this close to the inside of a triangle edge splits the edge (see _triangulate)
PathStatus = Literal["ok", "partial", "unreachable", "off_mesh"]


class NavmeshBuildError(ValueError):
    """The build produced a mesh that breaks an invariant (it is never returned)."""


@dataclass(frozen=True)
class NavmeshParams:
    """Build parameters, stored with the mesh.

    Attributes:
        agent_radius: radius the free space was eroded by, m.
        resolution: grid cell size, m.
        origin: (x_min, y_min) of the grid, m.
        shape: (rows, cols) of the grid.
        contour_error: simplification error ε, m (the boundary lies within ε inside the legal cells).
    """

    agent_radius: float
    resolution: float
    origin: tuple[float, float]
    shape: tuple[int, int]
    contour_error: float

    def to_array(self) -> np.ndarray:
        """The parameters as a float64 array (stored in navmesh.npz)."""
        return np.array(
            [NAVMESH_FORMAT, self.agent_radius, self.resolution, *self.origin, *self.shape, self.contour_error],
            dtype=np.float64,
        )

    @classmethod
    def from_array(cls, a: np.ndarray) -> NavmeshParams:
        """Inverse of :meth:`to_array`; refuses another navmesh format."""
        if int(a[0]) != NAVMESH_FORMAT:
            raise ValueError(f"navmesh format {int(a[0])} is not {NAVMESH_FORMAT}")
        return cls(float(a[1]), float(a[2]), (float(a[3]), float(a[4])), (int(a[5]), int(a[6])), float(a[7]))


@dataclass(frozen=True)
class PathResult:
    """A path query's answer.

    Attributes:
        status: ``ok`` (start to goal), ``partial`` (to the reachable point nearest the goal),
            ``unreachable`` (different mesh parts, partial not requested) or ``off_mesh`` (an end is
            farther than the snap distance from the mesh).
        points: (K, 2) float64 corner points from the snapped start to the (snapped) end, m; (0, 2)
            when there is no path.
        length: path length, m (inf when there is no path).
        reason: why the status is not ``ok``.
    """

    status: PathStatus
    points: np.ndarray
    length: float
    reason: str = ""


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def polyline_length(points: np.ndarray) -> float:
    """Length (m) of a (K, 2) polyline."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0


def funnel(portals_left: np.ndarray, portals_right: np.ndarray, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """String pulling through a channel of portals (Mononen's simple stupid funnel algorithm).

    Args:
        portals_left: (M, 2) float64 left portal ends (as seen walking from start to goal), m.
            Portal i is crossed after portal i − 1.
        portals_right: (M, 2) float64 right portal ends, m.
        start: (2,) float64, m; it lies before the first portal.
        goal: (2,) float64, m; it lies after the last portal.

    Returns:
        (K, 2) float64 corners from start to goal (the shortest path through the channel).
    """
    left = np.vstack([start, portals_left, goal])
    right = np.vstack([start, portals_right, goal])
    path = [np.asarray(start, dtype=np.float64)]
    apex, pl, pr = path[0], left[0], right[0]
    apex_i = li = ri = 0
    i, guard = 1, 4 * len(left) ** 2 + 16  # the restarts are bounded; the guard makes that explicit
    while i < len(left) and guard > 0:
        guard -= 1
        lp, rp = left[i], right[i]
        # tighten the right leg (rp must not be clockwise of it), unless it crosses the left leg
        if _cross(*(pr - apex), *(rp - apex)) >= 0.0:
            if np.array_equal(apex, pr) or _cross(*(pl - apex), *(rp - apex)) < 0.0:
                pr, ri = rp, i
            else:
                path.append(pl)
                apex, apex_i = pl, li
                pl = pr = apex
                li = ri = apex_i
                i = apex_i + 1
                continue
        if _cross(*(pl - apex), *(lp - apex)) <= 0.0:
            if np.array_equal(apex, pl) or _cross(*(pr - apex), *(lp - apex)) > 0.0:
                pl, li = lp, i
            else:
                path.append(pr)
                apex, apex_i = pr, ri
                pl = pr = apex
                li = ri = apex_i
                i = apex_i + 1
                continue
        i += 1
    if not np.array_equal(path[-1], goal):
        path.append(np.asarray(goal, dtype=np.float64))
    out = np.array(path)
    keep = np.ones(len(out), dtype=bool)
    keep[1:] = np.any(np.diff(out, axis=0) != 0.0, axis=1)
    return out[keep]


@dataclass
class Navmesh:
    """A triangulated navigation mesh (plain data; see :func:`build_navmesh`).

    Attributes:
        vertices: (V, 2) float64, m.
        triangles: (T, 3) int64 vertex ids, counter-clockwise.
        neighbours: (T, 3) int64 triangle across edge (t[k], t[k+1]), -1 on the boundary.
        segments: (S, 2) int64 boundary edges (vertex ids), the mesh on their left.
        seg_triangle: (S,) int64 the triangle each boundary edge belongs to.
        component: (T,) int64 connected part of each triangle.
        reflex: (R,) int64 reflex boundary vertices.
        vis_edges: (E, 2) int64 bitangent visible pairs of ``reflex`` positions (i < j).
        params: the build parameters.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    neighbours: np.ndarray
    segments: np.ndarray
    seg_triangle: np.ndarray
    component: np.ndarray
    reflex: np.ndarray
    vis_edges: np.ndarray
    params: NavmeshParams
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # ---- derived arrays -------------------------------------------------------------------------
    @property
    def seg_a(self) -> np.ndarray:
        """(S, 2) start points of the boundary segments, m."""
        return self.vertices[self.segments[:, 0]]

    @property
    def seg_b(self) -> np.ndarray:
        """(S, 2) end points of the boundary segments, m."""
        return self.vertices[self.segments[:, 1]]

    def _geometry(self) -> dict:
        """Flat arrays of the mesh's shape alone, built once: its vertices, triangles, walls and spatial hashes.

        ``verts, tris, va, vb`` (the walls' vertex ids), ``reflex, prev, next`` (each boundary vertex's
        neighbours along its ring) and the hashes ``grid, tstart, titems, sstart, sitems``. They depend
        only on the vertices, triangles and boundary segments, so :func:`navmesh_from_polygons` queries
        them (:meth:`locate`, the visibility graph) before it has filled in the fields that
        :meth:`_kernel` adds (the boundary edges' triangles, the visibility graph).
        """
        if "geometry" not in self._cache:
            verts = np.ascontiguousarray(self.vertices, dtype=np.float64)
            lo = verts.min(axis=0) - BUCKET_M if len(verts) else np.zeros(2)
            hi = verts.max(axis=0) + BUCKET_M if len(verts) else np.ones(2)
            n = np.maximum(np.ceil((hi - lo) / BUCKET_M).astype(np.int64), 1)
            tri = verts[self.triangles].reshape(-1, 3, 2)
            a, b = self.seg_a.reshape(-1, 2), self.seg_b.reshape(-1, 2)
            margin = 1e-4  # beyond rounding: a ray meets every wall it touches in the cells it walks
            tstart, titems = _k.hash_boxes(tri.min(axis=1) - margin, tri.max(axis=1) + margin, lo, n, BUCKET_M)
            sstart, sitems = _k.hash_boxes(np.minimum(a, b) - margin, np.maximum(a, b) + margin, lo, n, BUCKET_M)
            prev, nxt = _ring_links(len(verts), self.segments)
            self._cache["geometry"] = {
                "verts": verts,
                "tris": np.ascontiguousarray(self.triangles, dtype=np.int64),
                "va": np.ascontiguousarray(self.segments[:, 0], dtype=np.int64),
                "vb": np.ascontiguousarray(self.segments[:, 1], dtype=np.int64),
                "reflex": np.ascontiguousarray(self.reflex, dtype=np.int64),
                "prev": prev,
                "next": nxt,
                "grid": np.array([lo[0], lo[1], BUCKET_M, n[0], n[1]], dtype=np.float64),
                "tstart": tstart,
                "titems": titems,
                "sstart": sstart,
                "sitems": sitems,
            }
        return self._cache["geometry"]

    def _kernel(self) -> dict:
        """:meth:`_geometry`'s arrays plus the boundary edges' triangles and the visibility graph, built once.

        The flat arrays the compiled queries (:mod:`song.geometry._navmesh_kernel`) take.
        """
        if "kernel" not in self._cache:
            g = self._geometry()
            verts, reflex = g["verts"], g["reflex"]
            e = self.vis_edges.reshape(-1, 2)
            length = np.hypot(*(verts[reflex[e[:, 0]]] - verts[reflex[e[:, 1]]]).T)
            adj = sparse.csr_matrix(
                (np.r_[length, length], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                shape=(len(reflex),) * 2,
            )
            adj.sort_indices()
            self._cache["kernel"] = {
                **g,
                "seg_tri": np.ascontiguousarray(self.seg_triangle, dtype=np.int64),
                "seg_comp": np.ascontiguousarray(self.component[self.seg_triangle], dtype=np.int64),
                "vptr": adj.indptr.astype(np.int64),
                "vidx": adj.indices.astype(np.int64),
                "vlen": adj.data.astype(np.float64),
            }
            k = self._cache["kernel"]
            comp = np.ascontiguousarray(self.component, dtype=np.int64)
            names = ("verts", "tris", "seg_tri", "seg_comp", "va", "vb", "reflex", "prev", "next")
            tail = ("grid", "tstart", "titems", "sstart", "sitems", "vptr", "vidx", "vlen")
            self._cache["args"] = (*(k[n] for n in names), comp, *(k[n] for n in tail))
        return self._cache["kernel"]

    def _kernel_args(self) -> tuple:
        """The kernel arrays as the one tuple :func:`song.geometry._navmesh_kernel.find_path` takes."""
        self._kernel()
        return self._cache["args"]

    def move_args(self) -> tuple:
        """The kernel arrays compiled moves on the mesh take (``settle_moves`` of the crowd simulation).

        ``(va, vb, verts, tris, seg_tri, wall grid, wall start, wall items, triangle grid, triangle start,
        triangle items)``: enough for :meth:`constrain_moves`, :meth:`segment_clear` and :meth:`contains`.
        """
        if "move_args" not in self._cache:
            k = self._kernel()
            names = ("va", "vb", "verts", "tris", "seg_tri", "grid", "sstart", "sitems", "grid", "tstart", "titems")
            self._cache["move_args"] = tuple(k[n] for n in names)
        return self._cache["move_args"]

    @property
    def area(self) -> float:
        """Mesh area, m²."""
        t = self.vertices[self.triangles]
        return float(0.5 * _cross(*(t[:, 1] - t[:, 0]).T, *(t[:, 2] - t[:, 0]).T).sum())

    # ---- point queries --------------------------------------------------------------------------
    def locate(self, points: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Triangle containing each point, or -1.

        Args:
            points: (N, 2) float64, m.
            tol: points this far (m, roughly) outside a triangle still count as in it.

        Returns:
            (N,) int64 triangle ids.
        """
        g = self._geometry()  # not the kernel arrays: :func:`navmesh_from_polygons` locates before it can build them
        points = np.ascontiguousarray(np.atleast_2d(points), dtype=np.float64)
        return _k.locate(points, float(tol), g["verts"], g["tris"], g["grid"], g["tstart"], g["titems"])

    def nearest_boundary(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest boundary point to each point.

        Args:
            points: (N, 2) float64, m.

        Returns:
            ``(closest (N, 2), distance (N,), segment id (N,))``; the lowest segment id on ties.
        """
        k = self._kernel()
        points = np.ascontiguousarray(np.atleast_2d(points), dtype=np.float64)
        return _k.nearest_walls(points, k["va"], k["vb"], k["verts"])

    def snap(self, points: np.ndarray, max_dist: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest point of the mesh (the point itself when inside).

        Returns:
            ``(snapped (N, 2), triangle (N,) or -1 when farther than max_dist, distance moved (N,))``.
        """
        k = self._kernel()
        points = np.ascontiguousarray(np.atleast_2d(points), dtype=np.float64)
        return _k.snap(
            points,
            float(max_dist),
            k["verts"],
            k["tris"],
            k["seg_tri"],
            k["va"],
            k["vb"],
            k["grid"],
            k["tstart"],
            k["titems"],
        )

    def contains(self, points: np.ndarray, tol: float = 1e-6) -> np.ndarray:
        """(N,) bool: the point is on the mesh (within ``tol`` m of it)."""
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        inside = self.locate(points) >= 0
        if (~inside).any() and len(self.segments):
            _, dist, _ = self.nearest_boundary(points[~inside])
            inside[~inside] = dist <= tol
        return inside

    def segment_clear(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(N,) bool: the segments p→q (points on the mesh) stay on the mesh (touching walls is allowed).

        Args:
            p: (N, 2) float64 segment starts, m.
            q: (N, 2) float64 segment ends, m.
        """
        k = self._kernel()
        p = np.ascontiguousarray(np.atleast_2d(p), dtype=np.float64)
        q = np.ascontiguousarray(np.broadcast_to(np.atleast_2d(q), p.shape), dtype=np.float64)
        return _k.segments_clear(p, q, k["va"], k["vb"], k["verts"], k["grid"], k["sstart"], k["sitems"])

    def constrain_moves(self, pos: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Keep short moves on the mesh (DetourCrowd's move along the surface).

        A move whose segment leaves the mesh ends at the nearest mesh point to its target instead
        (sliding along the wall).

        Args:
            pos: (N, 2) float64 current positions on the mesh, m.
            target: (N, 2) float64 wanted positions, m.

        Returns:
            (N, 2) float64 positions on the mesh.
        """
        k = self._kernel()
        pos = np.ascontiguousarray(pos, dtype=np.float64)
        target = np.ascontiguousarray(target, dtype=np.float64)
        return _k.constrain_moves(
            pos, target, k["va"], k["vb"], k["verts"], k["tris"], k["seg_tri"], k["grid"], k["sstart"], k["sitems"]
        )

    # ---- paths ----------------------------------------------------------------------------------
    def corridor(self, start_tri: int, goal_tri: int, start: np.ndarray, goal: np.ndarray) -> list[int] | None:
        """A* over triangles with Detour's costs (between edge midpoints); None when unreachable."""
        if self.component[start_tri] != self.component[goal_tri]:
            return None
        tri, nb, v = self.triangles, self.neighbours, self.vertices
        came: dict[int, int] = {start_tri: -1}
        pos = {start_tri: np.asarray(start, dtype=np.float64)}
        g = {start_tri: 0.0}
        heap = [(float(np.linalg.norm(goal - start)), 0, start_tri)]
        closed: set[int] = set()
        tick = 0
        while heap:
            _, _, t = heapq.heappop(heap)
            if t == goal_tri:
                break
            if t in closed:
                continue
            closed.add(t)
            for k in range(3):
                n = int(nb[t, k])
                if n < 0 or n in closed:
                    continue
                mid = 0.5 * (v[tri[t, k]] + v[tri[t, (k + 1) % 3]]) if n != goal_tri else goal
                cost = g[t] + float(np.linalg.norm(mid - pos[t]))
                if cost < g.get(n, np.inf):
                    g[n], pos[n], came[n] = cost, mid, t
                    tick += 1
                    heapq.heappush(heap, (cost + float(np.linalg.norm(goal - mid)), tick, n))
        if goal_tri not in came:
            return None
        chain = [goal_tri]
        while came[chain[-1]] >= 0:
            chain.append(came[chain[-1]])
        return chain[::-1]

    def funnel_path(self, tris: list[int], start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """String-pulled corners through a triangle corridor (Detour's findStraightPath)."""
        left, right = [], []
        for t, n in zip(tris[:-1], tris[1:], strict=True):
            k = int(np.flatnonzero(self.neighbours[t] == n)[0])
            a, b = self.triangles[t, k], self.triangles[t, (k + 1) % 3]
            left.append(self.vertices[b])  # the triangle is CCW: walking out through edge a→b, b is on the left
            right.append(self.vertices[a])
        empty = np.zeros((0, 2))
        return funnel(np.array(left) if left else empty, np.array(right) if right else empty, start, goal)

    def find_path(
        self, start: np.ndarray, goal: np.ndarray, max_snap: float = 0.5, allow_partial: bool = True
    ) -> PathResult:
        """Shortest path on the mesh between two points (snapped to the mesh first).

        Args:
            start: (2,) float64, m.
            goal: (2,) float64, m.
            max_snap: farthest an end may be from the mesh, m.
            allow_partial: when the goal is in another mesh part, return a path to the point of the
                start's part nearest to the goal (status ``partial``) instead of ``unreachable``.
        """
        code, points, length = _k.find_path(
            float(start[0]),
            float(start[1]),
            float(goal[0]),
            float(goal[1]),
            float(max_snap),
            bool(allow_partial),
            self._kernel_args(),
        )
        if code in (_k.OK, _k.PARTIAL):
            reason = "" if code == _k.OK else "goal is on another part of the mesh"
            return PathResult("ok" if code == _k.OK else "partial", points, length, reason)
        reason = {
            _k.START_OFF: f"start is more than {max_snap} m from the mesh",
            _k.GOAL_OFF: f"goal is more than {max_snap} m from the mesh",
            _k.UNREACHABLE: "goal is on another part of the mesh",
            _k.NO_PATH: "no path between start and goal within one mesh part (a navmesh defect: please report it)",
        }[code]
        status = "off_mesh" if code in (_k.START_OFF, _k.GOAL_OFF) else "unreachable"
        return PathResult(status, np.zeros((0, 2)), float("inf"), reason)

    def distances(self, source: np.ndarray, goals: np.ndarray, max_snap: float = 0.5) -> np.ndarray:
        """Shortest-path lengths (m) from one point to many: one search over the visibility graph.

        Args:
            source: (2,) float64, m.
            goals: (N, 2) float64, m.
            max_snap: farthest an end may be from the mesh, m (the snap is not counted in the length).

        Returns:
            (N,) float64; inf where the goal is off the mesh or on another part of it.
        """
        goals = np.atleast_2d(np.asarray(goals, dtype=np.float64)).reshape(-1, 2)
        out = np.full(len(goals), np.inf)
        src, stri, _ = self.snap(np.asarray(source, dtype=np.float64)[None], max_snap)
        dst, gtri, _ = self.snap(goals, max_snap)
        if stri[0] < 0:
            return out
        ok = (gtri >= 0) & (self.component[np.maximum(gtri, 0)] == self.component[stri[0]])
        if ok.any():
            k = self._kernel()
            out[ok] = _k.distances_from(
                src[0, 0], src[0, 1], np.ascontiguousarray(dst[ok]), k["reflex"], k["verts"], k["prev"], k["next"],
                k["va"], k["vb"], k["grid"], k["sstart"], k["sitems"], k["vptr"], k["vidx"], k["vlen"],
            )  # fmt: skip
        return out


# ---- build ----------------------------------------------------------------------------------------
def trace_legal(legal: np.ndarray, resolution: float, origin: tuple[float, float]) -> list:
    """Polygons (shapely, world metres) of the legal cells, traced ¼ cell inside their outer edges.

    Args:
        legal: (rows, cols) bool grid of legal centres (image rows north-up, see ``song.geometry.grid``).
        resolution: cell size, m.
        origin: (x_min, y_min) of the grid, m.
    """
    import cv2
    import shapely
    from shapely.geometry import Polygon

    rows = legal.shape[0]
    up = np.repeat(np.repeat(legal.astype(np.uint8), 2, axis=0), 2, axis=1)
    contours, hierarchy = cv2.findContours(up, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    if hierarchy is None:
        return []

    def world(c: np.ndarray) -> np.ndarray:
        uv = c.reshape(-1, 2).astype(np.float64)  # (u = column, v = row) of the upsampled image
        return np.stack(
            [origin[0] + (uv[:, 0] + 0.5) / 2 * resolution, origin[1] + (rows - (uv[:, 1] + 0.5) / 2) * resolution], -1
        )

    polys = []
    for i, info in enumerate(hierarchy[0]):
        if info[3] >= 0 or len(contours[i]) < 3:
            continue
        holes, child = [], info[2]
        while child >= 0:
            if len(contours[child]) >= 3:
                holes.append(world(contours[child]))
            child = hierarchy[0][child][0]
        shape = Polygon(world(contours[i]), holes)
        if not shape.is_valid:
            # a hole touching its outer ring along an edge: make_valid of the whole polygon can keep the
            # outer ring and drop the hole (a mesh over furniture), so subtract the holes instead
            shape = shapely.make_valid(Polygon(world(contours[i])))
            if holes:
                shape = shape.difference(shapely.union_all([shapely.make_valid(Polygon(h)) for h in holes]))
        polys.extend(_polygon_parts(shape))
    return polys


def _polygon_parts(geometry) -> list:
    """The non-empty polygons of a geometry, at any nesting depth.

    ``make_valid`` of a contour whose hole touches the outer ring (a self-intersection) returns a
    GeometryCollection holding a MultiPolygon and a LineString; one level of ``geoms`` is not enough.
    """
    if geometry.geom_type == "Polygon":
        return [geometry] if geometry.area > 0 else []
    return [part for child in getattr(geometry, "geoms", []) for part in _polygon_parts(child)]


def simplify_polygons(polys: list, error: float, min_area: float = 0.0, margin: float = 0.0) -> list:
    """Douglas–Peucker at ε/2, then an inward mitred offset of max(ε/2 − margin, 0) + OFFSET_SLACK_M.

    ``margin`` is how far the input rings run inside the region the result must stay in (the traced
    rings run ¼ cell inside the legal cells' edges). Douglas–Peucker moves the boundary at most ε/2
    outward, so the offset keeps the result inside that region while cutting passages no more than
    needed (offsetting by the full ε/2 cut diagonal passages two cells wide that the grid keeps).

    Returns counter-clockwise polygons (holes clockwise) larger than ``min_area`` m².
    """
    from shapely.geometry.polygon import orient

    offset = max(0.5 * error - margin, 0.0) + OFFSET_SLACK_M
    out = []
    for poly in polys:
        shape = poly.simplify(0.5 * error, preserve_topology=True)
        shape = shape.buffer(-offset, join_style="mitre")
        out.extend(orient(g, 1.0) for g in getattr(shape, "geoms", [shape]) if g.area > max(min_area, 0.0))
    return sorted(out, key=lambda g: (round(g.bounds[0], 9), round(g.bounds[1], 9)))


def _triangulate(polys: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Earcut each polygon: ``(vertices (V, 2), triangles (T, 3) CCW, boundary segments (S, 2))``."""
    import mapbox_earcut

    verts, tris, segs, offset = [], [], [], 0
    for poly in polys:
        rings = [np.asarray(poly.exterior.coords)[:-1]] + [np.asarray(r.coords)[:-1] for r in poly.interiors]
        v = np.vstack(rings)
        ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
        t = mapbox_earcut.triangulate_float64(v, ends).reshape(-1, 3).astype(np.int64)
        ids = np.arange(len(v), dtype=np.int64)
        nxt = ids + 1  # each ring vertex links to the next, a ring's last back to its first
        nxt[ends.astype(np.int64) - 1] = np.concatenate([[0], ends[:-1]]).astype(np.int64)
        segs.append(np.stack([ids, nxt], -1) + offset)
        verts.append(v)
        tris.append(t + offset)
        offset += len(v)
    if not verts:
        return np.zeros((0, 2)), np.zeros((0, 3), np.int64), np.zeros((0, 2), np.int64)
    vertices, triangles = np.vstack(verts), np.vstack(tris)
    t = vertices[triangles]
    area = _cross(*(t[:, 1] - t[:, 0]).T, *(t[:, 2] - t[:, 0]).T)
    triangles[area < 0] = triangles[area < 0][:, ::-1]
    triangles = _k.split_t_junctions(vertices, triangles[np.abs(area) > 1e-14], T_JUNCTION_M)
    return vertices, triangles, np.vstack(segs)


def _adjacency(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """(T, 3) neighbour across edge k = (t[k], t[k+1]); -1 when no other triangle shares it."""
    e0, e1 = triangles, np.roll(triangles, -1, axis=1)
    key = (np.minimum(e0, e1) * n_vertices + np.maximum(e0, e1)).ravel()
    owner = np.repeat(np.arange(len(triangles)), 3)
    order = np.argsort(key, kind="stable")
    k, o = key[order], owner[order]
    same = np.flatnonzero(k[1:] == k[:-1])
    nb = np.full(key.shape, -1, dtype=np.int64)
    nb[order[same]], nb[order[same + 1]] = o[same + 1], o[same]
    return nb.reshape(-1, 3)


def _ring_links(n_vertices: int, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(prev, next)`` (V,) int64: each boundary vertex's neighbours along its ring (-1 off the boundary)."""
    prev = np.full(n_vertices, -1, dtype=np.int64)
    nxt = np.full(n_vertices, -1, dtype=np.int64)
    nxt[segments[:, 0]] = segments[:, 1]
    prev[segments[:, 1]] = segments[:, 0]
    return prev, nxt


def _reflex(vertices: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Boundary vertices where the mesh turns right (interior angle > 180°), sorted ids."""
    prev, nxt = _ring_links(len(vertices), segments)
    ids = segments[:, 0]
    d0 = vertices[ids] - vertices[prev[ids]]
    d1 = vertices[nxt[ids]] - vertices[ids]
    return np.sort(ids[_cross(*d0.T, *d1.T) < -TOUCH_EPS])


def _visibility_edges(mesh: Navmesh) -> np.ndarray:
    """(E, 2) pairs (i < j) of reflex positions joined by a bitangent segment that stays on the mesh.

    All reflex pairs are tried, but a pair costs two cross products unless it is bitangent, and a
    ray walks only the hash cells it crosses until its first wall, so the build grows about with the
    scene's area (not with its square, as a test of every pair against every wall did). It reads the
    mesh's shape (:meth:`Navmesh._geometry`), not the kernel arrays, which hold the graph it builds.
    """
    if len(mesh.reflex) < 2:
        return np.zeros((0, 2), np.int64)
    g = mesh._geometry()
    names = ("reflex", "verts", "prev", "next", "va", "vb", "grid", "sstart", "sitems")
    return _k.visibility_edges(*(g[n] for n in names))


def navmesh_from_polygons(polys: list, params: NavmeshParams) -> Navmesh:
    """Triangulate simplified polygons (CCW, holes CW) and derive adjacency, parts and the visibility graph."""
    vertices, triangles, segments = _triangulate(polys)
    neighbours = _adjacency(triangles, len(vertices))
    t, n = np.repeat(np.arange(len(triangles)), 3), neighbours.ravel()
    graph = sparse.csr_matrix((np.ones(int((n >= 0).sum())), (t[n >= 0], n[n >= 0])), shape=(len(triangles),) * 2)
    _, component = csgraph.connected_components(graph, directed=False)
    mesh = Navmesh(
        vertices=vertices,
        triangles=triangles,
        neighbours=neighbours,
        segments=segments,
        seg_triangle=np.zeros(len(segments), np.int64),
        component=component.astype(np.int64),
        reflex=_reflex(vertices, segments),
        vis_edges=np.zeros((0, 2), np.int64),
        params=params,
    )
    if len(segments):
        # the triangle of each boundary edge: the one containing a point just left of its midpoint
        a, b = mesh.seg_a, mesh.seg_b
        d = b - a
        inward = np.stack([-d[:, 1], d[:, 0]], -1) / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
        probe = 0.5 * (a + b) + inward * 1e-7
        mesh.seg_triangle = mesh.locate(probe, tol=1e-6)
        lost = mesh.seg_triangle < 0
        if lost.any():  # a sliver: fall back to the nearest triangle centroid
            centroid = vertices[triangles].mean(axis=1)
            mesh.seg_triangle[lost] = np.argmin(((probe[lost, None] - centroid[None]) ** 2).sum(-1), axis=1)
    mesh.vis_edges = _visibility_edges(mesh)
    return mesh  # the kernel arrays are built on first use, from the finished fields


def build_navmesh(
    legal: np.ndarray, resolution: float, origin: tuple[float, float], agent_radius: float, contour_error: float
) -> Navmesh:
    """The navmesh of a grid of legal centres (free space already eroded by ``agent_radius``).

    Args:
        legal: (rows, cols) bool, image rows north-up.
        resolution: m per cell.
        origin: (x_min, y_min), m.
        agent_radius: the erosion radius, m (recorded in the parameters).
        contour_error: simplification error ε, m (about one cell is Recast's default).
    """
    params = NavmeshParams(
        float(agent_radius),
        float(resolution),
        (float(origin[0]), float(origin[1])),
        (int(legal.shape[0]), int(legal.shape[1])),
        float(contour_error),
    )
    traced = trace_legal(legal, resolution, origin)
    polys = simplify_polygons(traced, contour_error, min_area=resolution**2, margin=0.25 * resolution)
    mesh = navmesh_from_polygons(polys, params)
    check_on_legal_cells(mesh, legal, resolution, origin)
    return mesh


def check_on_legal_cells(mesh: Navmesh, legal: np.ndarray, resolution: float, origin: tuple[float, float]) -> None:
    """Refuse a mesh that covers the centre of a cell where no agent may stand.

    The build keeps the mesh boundary at least ¼ cell inside the legal cells' outer edges, so the
    tolerance is zero cells: a covered illegal centre is a build defect (a lost hole puts the mesh
    over furniture), never a rounding effect.

    Raises:
        NavmeshBuildError: with the number of covered cells, their area and the first one's position.
    """
    if not len(mesh.triangles):
        return
    rows = legal.shape[0]
    r, c = np.nonzero(~legal)
    centres = np.stack([origin[0] + (c + 0.5) * resolution, origin[1] + (rows - r - 0.5) * resolution], -1)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    near = np.flatnonzero(((centres >= lo) & (centres <= hi)).all(axis=1))
    covered = near[mesh.locate(centres[near], tol=0.0) >= 0]
    if len(covered):
        x, y = centres[covered[0]]
        raise NavmeshBuildError(
            f"navmesh build: the mesh covers {len(covered)} occupied cell(s) "
            f"({len(covered) * resolution**2:.2f} m²), the first at ({x:.2f}, {y:.2f}) m"
        )


def navmesh_arrays(mesh: Navmesh) -> dict[str, np.ndarray]:
    """The mesh as plain arrays (for ``np.savez``); :func:`navmesh_from_arrays` reads them back."""
    return {
        "params": mesh.params.to_array(),
        "vertices": mesh.vertices,
        "triangles": mesh.triangles,
        "neighbours": mesh.neighbours,
        "segments": mesh.segments,
        "seg_triangle": mesh.seg_triangle,
        "component": mesh.component,
        "reflex": mesh.reflex,
        "vis_edges": mesh.vis_edges,
    }


def navmesh_from_arrays(arrays) -> Navmesh:
    """Inverse of :func:`navmesh_arrays` (``arrays``: a mapping such as an open ``np.load``)."""
    names = ("vertices", "triangles", "neighbours", "segments", "seg_triangle", "component", "reflex", "vis_edges")
    return Navmesh(**{k: np.asarray(arrays[k]) for k in names}, params=NavmeshParams.from_array(arrays["params"]))


def obstacle_rings(mesh: Navmesh, clearance: float) -> list[np.ndarray]:
    """Walls for ORCA: the mesh grown back by ``clearance`` (the un-eroded free space), in RVO2 order.

    RVO2 wants solid obstacles counter-clockwise and boundaries that enclose free space clockwise,
    so every outer ring of the grown free space is returned clockwise and every hole (a solid
    obstacle) counter-clockwise. Growing the mesh (rather than tracing the raw grid) keeps the walls
    exactly ``clearance`` from the mesh, so an agent on the mesh never overlaps a wall in ORCA's eyes.

    Returns:
        list of (K, 2) float64 rings, m.
    """
    import shapely
    from shapely.geometry import Polygon
    from shapely.geometry.polygon import orient

    polys = []
    for tri_ids in _component_rings(mesh):
        polys.append(Polygon(tri_ids[0], tri_ids[1:]))
    if not polys:
        return []
    grown = shapely.union_all([p.buffer(clearance, join_style="mitre") for p in polys])
    rings = []
    for g in sorted(getattr(grown, "geoms", [grown]), key=lambda g: g.bounds):
        g = orient(g.simplify(1e-4), 1.0)
        rings.append(np.asarray(g.exterior.coords)[:-1][::-1].copy())
        rings.extend(np.asarray(h.coords)[:-1][::-1].copy() for h in g.interiors)
    return rings


def _component_rings(mesh: Navmesh) -> list[list[np.ndarray]]:
    """Each mesh polygon as [exterior, *holes] coordinate rings, from the boundary segments."""
    from shapely.geometry import LineString
    from shapely.ops import polygonize

    lines = [LineString([a, b]) for a, b in zip(mesh.seg_a, mesh.seg_b, strict=True)]
    out = []
    for poly in polygonize(lines):
        # polygonize also returns the holes as faces; keep only faces that the mesh covers
        probe = poly.representative_point()
        if mesh.locate(np.array([[probe.x, probe.y]]))[0] >= 0:
            out.append([np.asarray(poly.exterior.coords)] + [np.asarray(h.coords) for h in poly.interiors])
    return out


def carve_discs(mesh: Navmesh, centres: np.ndarray, radius: float) -> Navmesh:
    """The mesh minus discs (Detour's temporary obstacles), re-triangulated.

    The mesh remembers its last ``CARVINGS_KEPT`` carvings (treat them as read-only).

    Args:
        mesh: the navmesh.
        centres: (M, 2) float64 disc centres, m.
        radius: disc radius, m (the polygons circumscribe the discs).
    """
    import shapely
    from shapely.geometry import Polygon
    from shapely.geometry.polygon import orient

    centres = np.ascontiguousarray(centres, dtype=np.float64).reshape(-1, 2)
    key = (float(radius), centres.tobytes())
    carvings = mesh._cache.setdefault("carvings", OrderedDict())
    if key in carvings:  # walkers stalled in the same frame meet the same people standing
        carvings.move_to_end(key)
        return carvings[key]
    if "region" not in mesh._cache:  # the mesh's polygons, the same for every carving (crowd replans)
        mesh._cache["region"] = shapely.union_all([Polygon(r[0], r[1:]) for r in _component_rings(mesh)])
    region = mesh._cache["region"]
    quad = 4
    grown = radius / np.cos(np.pi / (4 * quad))  # the 16-gon's edges touch the true circle
    holes = shapely.union_all(shapely.buffer(shapely.points(centres), grown, quad_segs=quad))
    shape = region.difference(holes)
    parts = [orient(g, 1.0) for g in getattr(shape, "geoms", [shape]) if g.geom_type == "Polygon" and g.area > 1e-6]
    carvings[key] = navmesh_from_polygons(sorted(parts, key=lambda g: g.bounds), mesh.params)
    if len(carvings) > CARVINGS_KEPT:
        carvings.popitem(last=False)
    return carvings[key]
