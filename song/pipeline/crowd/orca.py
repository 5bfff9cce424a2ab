"""ORCA (optimal reciprocal collision avoidance) with RVO2 semantics: parameters, obstacles, the step.

What :func:`orca_step` computes is what RVO2's ``RVOSimulator::doStep`` computes before it moves the
agents (``Agent::computeNeighbors`` + ``Agent::computeNewVelocity``), for every agent:

* agent neighbours: the ``max_neighbors`` nearest other agents strictly within ``neighbor_dist``,
  nearest first (RVO2's k-d tree query);
* obstacle neighbours: every obstacle edge that the agent sees from its outer (right) side within
  ``time_horizon_obst * max_speed + radius``, nearest first, ties in the order of RVO2's obstacle BSP
  tree walk (``KdTree::queryObstacleTreeRecursive``); the tree, with the edge splits RVO2 makes while
  building it, is built once by :func:`build_obstacles`;
* obstacle half-planes first (legs, cut-off line and circles, convexity, foreign legs, and the
  "already covered by an earlier obstacle line" test), then agent half-planes with reciprocal ½
  responsibility, cut off at ``time_horizon`` or, when two agents already overlap, at one time step;
* the new velocity: closest to the preferred one inside the max-speed disc and every half-plane
  (``linearProgram1/2``); where that is empty, the velocity that minimises the largest violation of
  the agent half-planes while keeping the obstacle ones hard (``linearProgram3``).

The arithmetic lives once in the compiled kernel (:mod:`song.pipeline.crowd._orca_kernel`) and once
in the plain reference twin (:mod:`song.pipeline.crowd._orca_reference`); tests compare the two and
compare both with RVO2 itself. Computes in float64 (RVO2 uses float32). Degenerate ties (two lines
within ``EPS`` of parallel, equal optima) may resolve differently from RVO2; every other result is the
same up to rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from song.pipeline.crowd._orca_kernel import EPS, lines_kernel, step_kernel


@dataclass(frozen=True)
class OrcaParams:
    """ORCA parameters shared by all agents (RVO2's agent defaults plus the simulator time step).

    Attributes:
        time_step: simulation step, s (the cut-off for agents already overlapping).
        neighbor_dist: agents strictly closer than this (m, centre to centre) are neighbours.
        max_neighbors: at most this many (the nearest) neighbours per agent.
        time_horizon: agent half-planes keep collisions out for this long, s.
        time_horizon_obst: obstacle half-planes keep collisions out for this long, s.
        static_full_responsibility: an agent takes the whole avoidance against a neighbour whose speed
            limit is 0 (a standing person cannot take its half); RVO2 always splits it (False).
        keep_pace: a feasible answer slower than the preferred velocity, still heading forward, is
            lengthened along its own direction toward the preferred speed as far as every half-plane
            allows (people keep their speed and turn rather than slow down when there is room); RVO2
            returns the allowed velocity nearest the preferred one (False).
    """

    time_step: float
    neighbor_dist: float
    max_neighbors: int
    time_horizon: float
    time_horizon_obst: float
    static_full_responsibility: bool = False
    keep_pace: bool = False


@dataclass(frozen=True)
class ObstacleSet:
    """Obstacle vertices as RVO2 holds them after ``processObstacles`` (edge splits included).

    Vertex v is the start of the edge v -> next[v]. Arrays: ``points`` (V, 2) float64 m,
    ``next``/``prev`` (V,) int64, ``directions`` (V, 2) unit edge directions, ``convex`` (V,) bool.
    The BSP tree has one node per vertex: ``node_left``/``node_right`` (V,) child vertex or -1,
    ``subtree`` (V,) node count of the subtree rooted at the vertex; ``ancestors`` (V, D) the path
    from the root (-1 padded) and ``in_left`` (V, D) whether the vertex lies in that ancestor's left
    subtree, used to order equally distant edges as the tree walk does.
    """

    points: np.ndarray
    next: np.ndarray
    prev: np.ndarray
    directions: np.ndarray
    convex: np.ndarray
    node_left: np.ndarray
    node_right: np.ndarray
    subtree: np.ndarray
    ancestors: np.ndarray
    in_left: np.ndarray
    root: int

    @property
    def n_vertices(self) -> int:
        """Number of obstacle vertices (after RVO2's edge splits)."""
        return len(self.points)


def _left_of(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """RVO2's ``leftOf``: > 0 when c is left of the directed line a -> b (arrays (..., 2))."""
    return (a[..., 0] - c[..., 0]) * (b[..., 1] - a[..., 1]) - (a[..., 1] - c[..., 1]) * (b[..., 0] - a[..., 0])


def _obstacle_vertices(polygons: list[np.ndarray]) -> tuple[list, list, list, list, list]:
    """RVO2's ``addObstacle`` for every polygon: ``(points, next, previous, unit directions, convex)``."""
    pts: list[np.ndarray] = []
    nxt: list[int] = []
    prv: list[int] = []
    dirs: list[np.ndarray] = []
    convex: list[bool] = []
    for poly in polygons:
        poly = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        k, base = len(poly), len(pts)
        if k < 2:
            continue
        for i in range(k):
            a, b, c = poly[i - 1], poly[i], poly[(i + 1) % k]
            pts.append(b.copy())
            nxt.append(base + (i + 1) % k)
            prv.append(base + (i - 1) % k)
            edge = c - b
            dirs.append(edge / np.hypot(*edge))
            convex.append(True if k == 2 else bool(_left_of(a, b, c) >= 0.0))
    return pts, nxt, prv, dirs, convex


def build_obstacles(polygons: list[np.ndarray]) -> ObstacleSet:
    """Obstacle vertices and RVO2's obstacle BSP tree (``addObstacle`` + ``processObstacles``).

    Args:
        polygons: each (K, 2) float64, m, in RVO2 vertex order: counter-clockwise around a solid
            obstacle, clockwise for a boundary that encloses free space. K == 2 is a single
            two-sided segment (as in RVO2); K < 2 is skipped, as RVO2 does.

    Returns:
        The obstacle set, including the vertices RVO2 adds where the tree splits an edge.
    """
    pts, nxt, prv, dirs, convex = _obstacle_vertices(polygons)
    left: list[int] = []
    right: list[int] = []

    def split_node(items: list[int]) -> int:
        """``buildObstacleTreeRecursive``: returns the root vertex of the subtree (-1 if empty)."""
        if not items:
            return -1
        p = np.array([pts[i] for i in items])
        q = np.array([pts[nxt[i]] for i in items])
        s1 = _left_of(p[:, None], q[:, None], p[None])  # [i, j]: side of j's start w.r.t. i's line
        s2 = _left_of(p[:, None], q[:, None], q[None])
        on_left = (s1 >= -EPS) & (s2 >= -EPS)
        on_right = ~on_left & (s1 <= EPS) & (s2 <= EPS)
        off = ~np.eye(len(items), dtype=bool)
        n_left = ((~on_right) & off).sum(1)  # left, or split (counts on both sides)
        n_right = ((~on_left) & off).sum(1)
        key = np.maximum(n_left, n_right) * (len(items) + 1) + np.minimum(n_left, n_right)
        best = int(np.argmin(key))  # first minimum of (max, min), as RVO2's strict "<"
        i1 = items[best]
        a, b = pts[i1], pts[nxt[i1]]
        lefts, rights = [], []
        for j, j1 in enumerate(items):
            if j == best:
                continue
            if on_left[best, j]:
                lefts.append(j1)
            elif on_right[best, j]:
                rights.append(j1)
            else:  # split edge j1 -> j2 where it crosses the line of edge i1
                j2 = nxt[j1]
                t = _cross(b - a, pts[j1] - a) / _cross(b - a, pts[j1] - pts[j2])
                new = len(pts)
                pts.append(pts[j1] + t * (pts[j2] - pts[j1]))
                dirs.append(dirs[j1])
                nxt.append(j2)
                prv.append(j1)
                convex.append(True)
                left.append(-1)
                right.append(-1)
                nxt[j1] = new
                prv[j2] = new
                if s1[best, j] > 0.0:
                    lefts.append(j1)
                    rights.append(new)
                else:
                    rights.append(j1)
                    lefts.append(new)
        left[i1] = split_node(lefts)
        right[i1] = split_node(rights)
        return i1

    left.extend([-1] * len(pts))
    right.extend([-1] * len(pts))
    root = split_node(list(range(len(pts))))
    return _finish_obstacles(pts, nxt, prv, dirs, convex, left, right, root)


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _finish_obstacles(pts, nxt, prv, dirs, convex, left, right, root) -> ObstacleSet:
    """Freeze the lists into arrays and precompute subtree sizes and root-to-node paths."""
    n = len(pts)
    subtree = np.zeros(n, dtype=np.int64)
    paths: list[list[tuple[int, bool]]] = [[] for _ in range(n)]
    order, stack = [], [root] if root >= 0 else []
    while stack:  # pre-order walk: parents before children
        v = stack.pop()
        order.append(v)
        for child, is_left in ((left[v], True), (right[v], False)):
            if child >= 0:
                paths[child] = [*paths[v], (v, is_left)]
                stack.append(child)
    for v in reversed(order):
        subtree[v] = 1 + sum(subtree[c] for c in (left[v], right[v]) if c >= 0)
    depth = max((len(p) for p in paths), default=0)
    ancestors = np.full((n, max(depth, 1)), -1, dtype=np.int64)
    in_left = np.zeros((n, max(depth, 1)), dtype=bool)
    for v, path in enumerate(paths):
        for k, (a, is_left) in enumerate(path):
            ancestors[v, k], in_left[v, k] = a, is_left
    return ObstacleSet(
        points=np.array(pts, dtype=np.float64).reshape(-1, 2),
        next=np.array(nxt, dtype=np.int64),
        prev=np.array(prv, dtype=np.int64),
        directions=np.array(dirs, dtype=np.float64).reshape(-1, 2),
        convex=np.array(convex, dtype=bool),
        node_left=np.array(left, dtype=np.int64),
        node_right=np.array(right, dtype=np.int64),
        subtree=subtree,
        ancestors=ancestors,
        in_left=in_left,
        root=int(root),
    )


_NO_OBSTACLES = (
    np.zeros((0, 2)),
    np.zeros(0, np.int64),
    np.zeros(0, np.int64),
    np.zeros((0, 2)),
    np.zeros(0, np.bool_),
    np.zeros(0, np.int64),
    np.zeros(0, np.int64),
    -1,
)


def _per_agent(values, n: int) -> np.ndarray:
    """(n,) contiguous float64 from a scalar or an array (no copy when it already is one: called every frame)."""
    if isinstance(values, np.ndarray) and values.shape == (n,) and values.dtype == np.float64:
        return np.ascontiguousarray(values)
    return np.ascontiguousarray(np.broadcast_to(np.asarray(values, dtype=np.float64), (n,)))


def _tree_args(obstacles: ObstacleSet | None) -> tuple:
    """The obstacle arrays as the kernels take them (built once per obstacle set)."""
    if obstacles is None or obstacles.n_vertices == 0:
        return _NO_OBSTACLES
    o = obstacles
    cached = o.__dict__.get("_tree_args")
    if cached is None:
        cached = (
            np.ascontiguousarray(o.points, dtype=np.float64),
            np.ascontiguousarray(o.next, dtype=np.int64),
            np.ascontiguousarray(o.prev, dtype=np.int64),
            np.ascontiguousarray(o.directions, dtype=np.float64),
            np.ascontiguousarray(o.convex, dtype=np.bool_),
            np.ascontiguousarray(o.node_left, dtype=np.int64),
            np.ascontiguousarray(o.node_right, dtype=np.int64),
            int(o.root),
        )
        object.__setattr__(o, "_tree_args", cached)  # a frozen dataclass: a private memo, not a field
    return cached


def kernel_tail(obstacles: ObstacleSet | None, params: OrcaParams) -> tuple:
    """What :func:`song.pipeline.crowd._orca_kernel.step_kernel` takes after the per-agent arrays.

    The obstacle arrays (built once per obstacle set) and the parameters, in the kernel's order; a
    caller stepping every frame builds it once.
    """
    scalars = (
        float(params.neighbor_dist),
        int(params.max_neighbors),
        float(params.time_horizon),
        float(params.time_horizon_obst),
        float(params.time_step),
        bool(params.static_full_responsibility),
        bool(params.keep_pace),
    )
    return (*_tree_args(obstacles), *scalars)


def _kernel_args(
    positions, velocities, radii, max_speeds, obstacles: ObstacleSet | None, params: OrcaParams, wall_radii=None
):
    pos = np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 2)
    n = len(pos)
    vel = np.ascontiguousarray(velocities, dtype=np.float64).reshape(-1, 2)
    walls = _per_agent(radii if wall_radii is None else wall_radii, n)
    radii, speeds = _per_agent(radii, n), _per_agent(max_speeds, n)
    return pos, vel, (radii, walls), speeds, kernel_tail(obstacles, params)


def orca_step(
    positions: np.ndarray,
    velocities: np.ndarray,
    pref_velocities: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    obstacles: ObstacleSet | None,
    params: OrcaParams,
    wall_radii: np.ndarray | None = None,
) -> np.ndarray:
    """New velocities of all agents (RVO2's ``computeNewVelocity`` for each).

    Args:
        positions: (N, 2) m.
        velocities: (N, 2) current velocities, m/s.
        pref_velocities: (N, 2) preferred velocities, m/s.
        radii: (N,) or scalar: radii against other agents, m.
        wall_radii: (N,) or scalar radii against the walls (default: ``radii``), m.
        max_speeds: (N,) or scalar, m/s.
        obstacles: walls from :func:`build_obstacles`, or None.
        params: shared ORCA parameters.

    Returns:
        (N, 2) float64 new velocities, m/s.
    """
    pos, vel, (radii, walls), speeds, tail = _kernel_args(
        positions, velocities, radii, max_speeds, obstacles, params, wall_radii
    )
    pref = np.ascontiguousarray(pref_velocities, dtype=np.float64).reshape(-1, 2)
    return step_kernel(pos, vel, pref, radii, walls, speeds, *tail)


def orca_lines(
    positions: np.ndarray,
    velocities: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    obstacles: ObstacleSet | None,
    params: OrcaParams,
) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """Each agent's ORCA half-planes, as RVO2 builds them (``Agent::orcaLines_``).

    Returns:
        per agent ``(points (L, 2), directions (L, 2), n_obstacle_lines)``; obstacle lines come first,
        velocities left of a line's direction are allowed.
    """
    pos, vel, (radii, walls), speeds, tail = _kernel_args(positions, velocities, radii, max_speeds, obstacles, params)
    lines, counts, n_obstacle = lines_kernel(pos, vel, radii, walls, speeds, *tail)
    return [
        (lines[i, :c, :2], lines[i, :c, 2:], int(k)) for i, (c, k) in enumerate(zip(counts, n_obstacle, strict=True))
    ]
