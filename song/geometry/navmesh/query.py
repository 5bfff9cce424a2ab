"""Detour's queries on a built mesh: locate, snap, lines of sight, moves, corridors and exact paths.

:class:`NavmeshQueries` holds the query methods of :class:`~song.geometry.navmesh.mesh.Navmesh` (its
data and cached kernel arrays live in :mod:`song.geometry.navmesh.mesh`). The arithmetic is compiled
(:mod:`song.geometry._navmesh_kernel`; reference twin :mod:`song.geometry._navmesh_reference`).
Nothing raises on a bad query: :meth:`NavmeshQueries.find_path` returns a :class:`PathResult` whose
status (``ok`` / ``partial`` / ``unreachable`` / ``off_mesh``) carries its reason, as Detour's
``dtStatus`` does.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import Literal

import numpy as np

from song.geometry import _navmesh_kernel as _k

PathStatus = Literal["ok", "partial", "unreachable", "off_mesh"]


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


class NavmeshQueries:
    """The query methods of a navmesh (mixed into :class:`~song.geometry.navmesh.mesh.Navmesh`)."""

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
