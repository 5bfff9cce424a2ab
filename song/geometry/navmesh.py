"""Navigation mesh over a grid of legal agent centres: Recast's build, Detour's queries, exact paths.

Build (Recast semantics; the caller erodes free space by the agent radius, so every point of the mesh
is a legal centre):

1. Contours of the legal cells are traced with OpenCV on a 2× upsampled mask (so one-cell-wide
   passages keep a non-zero width); the traced rings run ¼ cell inside the cells' outer edges.
2. Simplification with error ε (``contour_error``): Douglas–Peucker with tolerance ε/2, then an inward
   offset of ε/2 (mitred). Douglas–Peucker keeps every point within ε/2 of the traced ring, so the
   offset result lies inside the traced region: the mesh never leaves the legal cells, and its
   boundary is at most ε (about one cell) inside them.
3. Triangulation with mapbox-earcut (chosen over shapely's constrained Delaunay: it returns vertex
   indices directly, handles holes, and is several times faster; triangle shape does not matter
   here because paths come from the funnel and the visibility graph, not from triangle centres).
4. Triangle adjacency (shared vertex pairs), connected components, reflex vertices of the boundary and
   the reduced visibility graph between them (bitangent, unobstructed pairs).

Queries (Detour semantics plus exactness): nearest-polygon snapping; A* over triangles with Detour's
edge-midpoint costs and the funnel (string pulling) over its portals; and the true shortest path
within the mesh from the reduced visibility graph (shortest paths in a polygonal domain bend only at
reflex vertices, on bitangent edges). ``find_path`` returns the shorter of the two, which is always
the visibility-graph path up to rounding. Nothing raises on a bad query: a :class:`PathResult`
carries ``ok`` / ``partial`` / ``unreachable`` / ``off_mesh`` and a reason.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

NAVMESH_FORMAT = 1
TOUCH_EPS = 1e-12  # |cross| below this (m²) counts as collinear in segment tests (coordinates are ≤ 1 km)
SHORTEN_M = 1e-7  # query segments are shortened by this at both ends so that touching an endpoint's walls is not a hit
NUDGE_M = 1e-6  # projected points are moved this far into their triangle, so they are strictly inside
BUCKET_M = 0.5  # cell size of the spatial hash used for local segment and triangle look-ups
PathStatus = Literal["ok", "partial", "unreachable", "off_mesh"]


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


def segments_blocked(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether query segments p→q hit wall segments a→b (crossing or touching, not collinear).

    Args:
        p: (..., 2) float64 query segment starts, m.
        q: (..., 2) float64 query segment ends, m.
        a: (..., 2) float64 wall segment starts, m (broadcast against p, q).
        b: (..., 2) float64 wall segment ends, m.

    Returns:
        (...) bool. Collinear overlaps do not count (a path may run along a wall).
    """
    dx, dy = q[..., 0] - p[..., 0], q[..., 1] - p[..., 1]
    ex, ey = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    o1 = _cross(dx, dy, a[..., 0] - p[..., 0], a[..., 1] - p[..., 1])
    o2 = _cross(dx, dy, b[..., 0] - p[..., 0], b[..., 1] - p[..., 1])
    o3 = _cross(ex, ey, p[..., 0] - a[..., 0], p[..., 1] - a[..., 1])
    o4 = _cross(ex, ey, q[..., 0] - a[..., 0], q[..., 1] - a[..., 1])
    o1, o2, o3, o4 = (np.where(np.abs(o) < TOUCH_EPS, 0.0, o) for o in (o1, o2, o3, o4))
    collinear = (o1 == 0.0) & (o2 == 0.0)
    return (o1 * o2 <= 0.0) & (o3 * o4 <= 0.0) & ~collinear


def nearest_on_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segments to points, pairwise over (N,) × (S,).

    Returns:
        ``(closest (N, S, 2), dist (N, S))`` in metres.
    """
    d = b - a
    len2 = np.maximum((d**2).sum(-1), 1e-300)
    t = np.clip(((points[:, None, :] - a[None]) * d[None]).sum(-1) / len2[None], 0.0, 1.0)
    closest = a[None] + t[..., None] * d[None]
    return closest, np.linalg.norm(points[:, None, :] - closest, axis=-1)


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


def _hash_boxes(lo: np.ndarray, hi: np.ndarray, origin: np.ndarray, n_cells: np.ndarray) -> np.ndarray:
    """Spatial hash: (C, K) item ids per bucket (padded with -1) for items with bounding boxes lo/hi (M, 2)."""
    i0 = np.clip(np.floor((lo - origin) / BUCKET_M).astype(np.int64), 0, n_cells - 1)
    i1 = np.clip(np.floor((hi - origin) / BUCKET_M).astype(np.int64), 0, n_cells - 1)
    nx, ny = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
    count = nx * ny
    item = np.repeat(np.arange(len(lo)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    cell = (i0[item, 1] + k // nx[item]) * n_cells[0] + i0[item, 0] + k % nx[item]
    order = np.lexsort((item, cell))
    cell, item = cell[order], item[order]
    per = np.bincount(cell, minlength=int(n_cells.prod()))
    table = np.full((len(per), max(1, int(per.max(initial=0)))), -1, dtype=np.int64)
    slot = np.arange(len(cell)) - np.repeat(np.cumsum(per) - per, per)
    table[cell, slot] = item
    return table


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

    def _hash(self) -> dict:
        if "hash" not in self._cache:
            lo_all = self.vertices.min(axis=0) - BUCKET_M
            n = np.maximum(np.ceil((self.vertices.max(axis=0) + BUCKET_M - lo_all) / BUCKET_M).astype(np.int64), 1)
            tri = self.vertices[self.triangles]
            a, b = self.seg_a, self.seg_b
            margin = 0.1  # a local query (a step of a few cm) may reach this far beyond its bucket
            self._cache["hash"] = {
                "origin": lo_all,
                "n": n,
                "tri": _hash_boxes(tri.min(axis=1), tri.max(axis=1), lo_all, n),
                "seg": _hash_boxes(np.minimum(a, b) - margin, np.maximum(a, b) + margin, lo_all, n),
            }
        return self._cache["hash"]

    def _bucket(self, points: np.ndarray, kind: str) -> np.ndarray:
        h = self._hash()
        ij = np.clip(np.floor((points - h["origin"]) / BUCKET_M).astype(np.int64), 0, h["n"] - 1)
        return h[kind][ij[:, 1] * h["n"][0] + ij[:, 0]]

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
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        cand = self._bucket(points, "tri")  # (N, K)
        t = self.vertices[self.triangles[np.maximum(cand, 0)]]  # (N, K, 3, 2)
        p = points[:, None, None, :]
        e = np.roll(t, -1, axis=2) - t
        length = np.maximum(np.linalg.norm(e, axis=-1), 1e-300)
        side = _cross(e[..., 0], e[..., 1], p[..., 0] - t[..., 0], p[..., 1] - t[..., 1]) / length
        inside = (side >= -tol).all(axis=-1) & (cand >= 0)
        first = np.argmax(inside, axis=1)
        return np.where(inside.any(axis=1), cand[np.arange(len(points)), first], -1)

    def nearest_boundary(self, points: np.ndarray, local: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest boundary point to each point.

        Args:
            points: (N, 2) float64, m.
            local: only look at walls hashed near each point (for points within ~0.1 m of the mesh).

        Returns:
            ``(closest (N, 2), distance (N,), segment id (N,))``.
        """
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        a, b = self.seg_a, self.seg_b
        if local:
            cand = self._bucket(points, "seg")
            safe = np.maximum(cand, 0)
            d = b[safe] - a[safe]
            len2 = np.maximum((d**2).sum(-1), 1e-300)
            t = np.clip(((points[:, None] - a[safe]) * d).sum(-1) / len2, 0.0, 1.0)
            closest = a[safe] + t[..., None] * d
            dist = np.where(cand >= 0, np.linalg.norm(points[:, None] - closest, axis=-1), np.inf)
        else:
            closest, dist = nearest_on_segments(points, a, b)
            cand = np.broadcast_to(np.arange(len(a)), dist.shape)
        k = np.argmin(dist, axis=1)
        rows = np.arange(len(points))
        return closest[rows, k], dist[rows, k], cand[rows, k]

    def nudge_inside(self, points: np.ndarray, segment: np.ndarray) -> np.ndarray:
        """Move boundary points NUDGE_M toward the centroid of their boundary edge's triangle."""
        centroid = self.vertices[self.triangles[self.seg_triangle[segment]]].mean(axis=1)
        d = centroid - points
        return points + d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300) * NUDGE_M

    def snap(self, points: np.ndarray, max_dist: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest point of the mesh (the point itself when inside).

        Returns:
            ``(snapped (N, 2), triangle (N,) or -1 when farther than max_dist, distance moved (N,))``.
        """
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        tri = self.locate(points)
        out, moved = points.copy(), np.zeros(len(points))
        off = np.flatnonzero(tri < 0)
        if len(off) and len(self.segments):
            closest, dist, seg = self.nearest_boundary(points[off])
            near = dist <= max_dist
            out[off] = np.where(near[:, None], self.nudge_inside(closest, seg), points[off])
            moved[off] = np.where(near, dist, np.inf)
            tri[off] = np.where(near, self.seg_triangle[seg], -1)
        return out, tri, moved

    def contains(self, points: np.ndarray, tol: float = 1e-6) -> np.ndarray:
        """(N,) bool: the point is on the mesh (within ``tol`` m of it)."""
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        inside = self.locate(points) >= 0
        if (~inside).any():
            _, dist, _ = self.nearest_boundary(points[~inside])
            inside[~inside] = dist <= tol
        return inside

    def segment_clear(self, p: np.ndarray, q: np.ndarray, chunk: int = 200_000) -> np.ndarray:
        """(N,) bool: the segments p→q (points on the mesh) stay on the mesh (touching walls is allowed).

        Args:
            p: (N, 2) float64 segment starts, m.
            q: (N, 2) float64 segment ends, m.
            chunk: segments tested per batch (bounds the temporary arrays).
        """
        p, q = np.atleast_2d(p).astype(np.float64), np.atleast_2d(q).astype(np.float64)
        d = q - p
        n = np.linalg.norm(d, axis=1, keepdims=True)
        u = d / np.maximum(n, 1e-300)
        s = np.minimum(SHORTEN_M, 0.5 * n)
        p2, q2 = p + u * s, q - u * s
        a, b = self.seg_a, self.seg_b
        out = np.ones(len(p), dtype=bool)
        step = max(1, chunk // max(1, len(a)))
        for i in range(0, len(p), step):
            # bounding-box prefilter, then the exact test on the few walls that can be hit
            lo = np.minimum(p2[i : i + step], q2[i : i + step])
            hi = np.maximum(p2[i : i + step], q2[i : i + step])
            near = (
                (np.minimum(a, b)[None] <= hi[:, None]).all(-1) & (np.maximum(a, b)[None] >= lo[:, None]).all(-1)
            ).any(axis=0)
            if near.any():
                hit = segments_blocked(p2[i : i + step, None], q2[i : i + step, None], a[near][None], b[near][None])
                out[i : i + step] = ~hit.any(axis=1)
        return out

    def constrain_moves(self, pos: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Keep short moves on the mesh (DetourCrowd's move along the surface).

        A move whose segment leaves the mesh ends at the nearest mesh point to its target instead
        (sliding along the wall). Moves are expected to be short (≲ 0.1 m).

        Args:
            pos: (N, 2) float64 current positions on the mesh, m.
            target: (N, 2) float64 wanted positions, m.

        Returns:
            (N, 2) float64 positions on the mesh.
        """
        cand = self._bucket(pos, "seg")
        safe = np.maximum(cand, 0)
        a, b = self.seg_a[safe], self.seg_b[safe]  # (N, K, 2)
        hit = segments_blocked(pos[:, None], target[:, None], a, b)
        bad = np.flatnonzero((hit & (cand >= 0)).any(axis=1))
        out = target.copy()
        if len(bad):
            closest, _, seg = self.nearest_boundary(target[bad], local=True)
            out[bad] = self.nudge_inside(closest, seg)
        return out

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

    def _tangent(self, vids: np.ndarray, other: np.ndarray) -> np.ndarray:
        """(N,) bool: the line from reflex vertex ``vids`` to ``other`` (N, 2) leaves both of its walls on one side."""
        prev, nxt = self._cache.get("prev"), self._cache.get("next")
        if prev is None:
            prev = np.full(len(self.vertices), -1)
            nxt = np.full(len(self.vertices), -1)
            nxt[self.segments[:, 0]] = self.segments[:, 1]
            prev[self.segments[:, 1]] = self.segments[:, 0]
            self._cache["prev"], self._cache["next"] = prev, nxt
        v = self.vertices[vids]
        d = other - v
        s1 = _cross(*d.T, *(self.vertices[prev[vids]] - v).T)
        s2 = _cross(*d.T, *(self.vertices[nxt[vids]] - v).T)
        s1[np.abs(s1) < TOUCH_EPS] = 0.0
        s2[np.abs(s2) < TOUCH_EPS] = 0.0
        return s1 * s2 >= 0.0

    def _visible_reflex(self, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Reflex positions visible from ``point`` along tangent lines, and their distances."""
        v = self.vertices[self.reflex]
        ok = self._tangent(self.reflex, np.broadcast_to(point, v.shape))
        idx = np.flatnonzero(ok)
        if len(idx):
            idx = idx[self.segment_clear(np.broadcast_to(point, (len(idx), 2)), v[idx])]
        return idx, np.linalg.norm(v[idx] - point, axis=1)

    def shortest_path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """The true shortest path between two points of one mesh part (reduced visibility graph)."""
        start, goal = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
        if self.segment_clear(start[None], goal[None])[0]:
            return np.array([start, goal])
        r = len(self.reflex)
        si, sd = self._visible_reflex(start)
        gi, gd = self._visible_reflex(goal)
        e = self.vis_edges
        w = np.linalg.norm(self.vertices[self.reflex[e[:, 0]]] - self.vertices[self.reflex[e[:, 1]]], axis=1)
        rows = np.concatenate([e[:, 0], e[:, 1], np.full(len(si), r), gi])
        cols = np.concatenate([e[:, 1], e[:, 0], si, np.full(len(gi), r + 1)])
        data = np.concatenate([w, w, sd, gd])
        graph = sparse.csr_matrix((np.maximum(data, 1e-12), (rows, cols)), shape=(r + 2, r + 2))
        dist, pred = csgraph.dijkstra(graph, directed=True, indices=r, return_predecessors=True)
        if not np.isfinite(dist[r + 1]):
            return None
        chain = [r + 1]
        while pred[chain[-1]] >= 0:
            chain.append(int(pred[chain[-1]]))
        nodes = np.array(chain[::-1][1:-1], dtype=np.int64)
        return np.vstack([start, self.vertices[self.reflex[nodes]], goal])

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
        none = np.zeros((0, 2))
        ends, tri, moved = self.snap(np.array([start, goal], dtype=np.float64), max_snap)
        if (tri < 0).any():
            which = "start" if tri[0] < 0 else "goal"
            return PathResult("off_mesh", none, float("inf"), f"{which} is more than {max_snap} m from the mesh")
        status, reason = "ok", ""
        if self.component[tri[0]] != self.component[tri[1]]:
            if not allow_partial:
                return PathResult("unreachable", none, float("inf"), "goal is on another part of the mesh")
            mine = self.component[self.seg_triangle] == self.component[tri[0]]
            closest, dist = nearest_on_segments(ends[1:], self.seg_a[mine], self.seg_b[mine])
            k = int(np.argmin(dist[0]))
            ends[1] = self.nudge_inside(closest[0, k][None], np.flatnonzero(mine)[k : k + 1])[0]
            tri[1] = self.seg_triangle[np.flatnonzero(mine)[k]]
            status, reason = "partial", "goal is on another part of the mesh"
        best = self.shortest_path(ends[0], ends[1])
        corridor = self.corridor(int(tri[0]), int(tri[1]), ends[0], ends[1])
        if corridor is not None:
            pulled = self.funnel_path(corridor, ends[0], ends[1])
            if best is None or polyline_length(pulled) < polyline_length(best) - 1e-9:
                best = pulled
        if best is None:  # cannot happen for one mesh part; kept so that a query never raises
            return PathResult("unreachable", none, float("inf"), "no corridor between start and goal")
        return PathResult(status, best, polyline_length(best), reason)


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
        polys.extend(_polygon_parts(shapely.make_valid(Polygon(world(contours[i]), holes))))
    return polys


def _polygon_parts(geometry) -> list:
    """The non-empty polygons of a geometry, at any nesting depth.

    ``make_valid`` of a contour whose hole touches the outer ring (a self-intersection) returns a
    GeometryCollection holding a MultiPolygon and a LineString; one level of ``geoms`` is not enough.
    """
    if geometry.geom_type == "Polygon":
        return [geometry] if geometry.area > 0 else []
    return [part for child in getattr(geometry, "geoms", []) for part in _polygon_parts(child)]


def simplify_polygons(polys: list, error: float, min_area: float = 0.0) -> list:
    """Douglas–Peucker at ε/2, then an inward mitred offset of ε/2: the result stays inside ``polys``.

    Returns counter-clockwise polygons (holes clockwise) larger than ``min_area`` m².
    """
    from shapely.geometry.polygon import orient

    out = []
    for poly in polys:
        shape = poly.simplify(0.5 * error, preserve_topology=True).buffer(-0.5 * error, join_style="mitre")
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
        start = np.concatenate([[0], ends[:-1]]).astype(np.int64)
        for s, e in zip(start, ends.astype(np.int64), strict=True):
            ids = np.arange(s, e)
            segs.append(np.stack([ids, np.roll(ids, -1)], -1) + offset)
        verts.append(v)
        tris.append(t + offset)
        offset += len(v)
    if not verts:
        return np.zeros((0, 2)), np.zeros((0, 3), np.int64), np.zeros((0, 2), np.int64)
    vertices, triangles = np.vstack(verts), np.vstack(tris)
    t = vertices[triangles]
    area = _cross(*(t[:, 1] - t[:, 0]).T, *(t[:, 2] - t[:, 0]).T)
    triangles[area < 0] = triangles[area < 0][:, ::-1]
    triangles = triangles[np.abs(area) > 1e-14]
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


def _reflex(vertices: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Boundary vertices where the mesh turns right (interior angle > 180°), sorted ids."""
    nxt = np.full(len(vertices), -1)
    prev = np.full(len(vertices), -1)
    nxt[segments[:, 0]] = segments[:, 1]
    prev[segments[:, 1]] = segments[:, 0]
    ids = segments[:, 0]
    d0 = vertices[ids] - vertices[prev[ids]]
    d1 = vertices[nxt[ids]] - vertices[ids]
    return np.sort(ids[_cross(*d0.T, *d1.T) < -TOUCH_EPS])


def _visibility_edges(mesh: Navmesh) -> np.ndarray:
    """(E, 2) pairs (i < j) of reflex positions joined by a bitangent segment that stays on the mesh."""
    r = len(mesh.reflex)
    if r < 2:
        return np.zeros((0, 2), np.int64)
    i, j = np.triu_indices(r, k=1)
    vi, vj = mesh.reflex[i], mesh.reflex[j]
    ok = mesh._tangent(vi, mesh.vertices[vj]) & mesh._tangent(vj, mesh.vertices[vi])
    i, j = i[ok], j[ok]
    clear = mesh.segment_clear(mesh.vertices[mesh.reflex[i]], mesh.vertices[mesh.reflex[j]])
    return np.stack([i[clear], j[clear]], -1).astype(np.int64)


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
    return mesh


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
    polys = simplify_polygons(trace_legal(legal, resolution, origin), contour_error, min_area=resolution**2)
    return navmesh_from_polygons(polys, params)


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

    Args:
        mesh: the navmesh.
        centres: (M, 2) float64 disc centres, m.
        radius: disc radius, m (the polygons circumscribe the discs).
    """
    import shapely
    from shapely.geometry import Polygon
    from shapely.geometry.polygon import orient

    region = shapely.union_all([Polygon(r[0], r[1:]) for r in _component_rings(mesh)])
    quad = 4
    grown = radius / np.cos(np.pi / (4 * quad))  # the 16-gon's edges touch the true circle
    holes = shapely.union_all(shapely.buffer(shapely.points(np.asarray(centres).reshape(-1, 2)), grown, quad_segs=quad))
    shape = region.difference(holes)
    parts = [orient(g, 1.0) for g in getattr(shape, "geoms", [shape]) if g.geom_type == "Polygon" and g.area > 1e-6]
    return navmesh_from_polygons(sorted(parts, key=lambda g: g.bounds), mesh.params)
