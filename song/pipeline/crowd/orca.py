"""ORCA (optimal reciprocal collision avoidance), vectorised over agents in numpy, with RVO2 semantics.

What one call of :func:`orca_step` computes is what RVO2's ``RVOSimulator::doStep`` computes before it
moves the agents (``Agent::computeNeighbors`` + ``Agent::computeNewVelocity``), for all agents at once:

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

How it is vectorised. Lines live in padded ``(N, L)`` arrays (obstacle slots first, then agent slots);
an unused slot holds a line that the whole max-speed disc satisfies and that never bounds another, so
no masks are needed in the LP. The 2-D LP is solved for all agents with no loop over constraints: its
optimum is unique, and it is either the (disc-clipped) preferred velocity or, for some line i, the
point of line i closest to the preferred velocity within the interval that the disc and *all* other
lines leave on line i -- the same point RVO2's incremental algorithm ends on, computed from all
``(N, L, L)`` line pairs at once. Agents whose 2-D LP is infeasible (dense crowds; rare) rerun the
incremental 2-D LP (to learn where it fails, which ``linearProgram3`` starts from) and then the 3-D LP,
one line at a time for all of them together, with the inner direction-optimising 2-D LPs solved the
same loop-free way. ``_reference.py`` is the plain one-agent-at-a-time transcription it is tested
against.

Computes in float64 (RVO2 uses float32). Degenerate ties (two lines within ``EPS`` of parallel, equal
optima) may resolve differently from RVO2; every other result is the same up to rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

EPS = 1e-5  # RVO_EPSILON: parallel-line threshold in the LPs, side tests in the obstacle tree
FAR = 1e6  # offset (m/s) of the filler line in unused slots: far outside any max-speed disc
DENSE_NEIGHBOURS_MAX_N = 96  # up to this many agents a dense distance matrix beats a k-d tree


@dataclass(frozen=True)
class OrcaParams:
    """ORCA parameters shared by all agents (RVO2's agent defaults plus the simulator time step).

    Attributes:
        time_step: simulation step, s (the cut-off for agents already overlapping).
        neighbor_dist: agents strictly closer than this (m, centre to centre) are neighbours.
        max_neighbors: at most this many (the nearest) neighbours per agent.
        time_horizon: agent half-planes keep collisions out for this long, s.
        time_horizon_obst: obstacle half-planes keep collisions out for this long, s.
    """

    time_step: float
    neighbor_dist: float
    max_neighbors: int
    time_horizon: float
    time_horizon_obst: float


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
        return len(self.points)


def _left_of(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """RVO2's ``leftOf``: > 0 when c is left of the directed line a -> b (arrays (..., 2))."""
    return (a[..., 0] - c[..., 0]) * (b[..., 1] - a[..., 1]) - (a[..., 1] - c[..., 1]) * (b[..., 0] - a[..., 0])


def build_obstacles(polygons: list[np.ndarray]) -> ObstacleSet:
    """Obstacle vertices and RVO2's obstacle BSP tree (``addObstacle`` + ``processObstacles``).

    Args:
        polygons: each (K, 2) float64, m, in RVO2 vertex order: counter-clockwise around a solid
            obstacle, clockwise for a boundary that encloses free space. K == 2 is a single
            two-sided segment (as in RVO2); K < 2 is skipped, as RVO2 does.

    Returns:
        The obstacle set, including the vertices RVO2 adds where the tree splits an edge.
    """
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


def _agent_neighbours(positions: np.ndarray, params: OrcaParams) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour indices (N, K) nearest first (ties by index) and their validity mask (N, K)."""
    n = len(positions)
    k = min(params.max_neighbors, n - 1)
    if k <= 0:
        return np.zeros((n, 0), dtype=np.int64), np.zeros((n, 0), dtype=bool)
    range_sq = params.neighbor_dist**2
    if n <= DENSE_NEIGHBOURS_MAX_N:
        dx = positions[:, None, 0] - positions[None, :, 0]
        dy = positions[:, None, 1] - positions[None, :, 1]
        d2 = dx * dx + dy * dy
        d2[np.arange(n), np.arange(n)] = np.inf
        idx = np.argsort(d2, axis=1, kind="stable")[:, :k]
        return idx, np.take_along_axis(d2, idx, axis=1) < range_sq
    _, idx = cKDTree(positions, balanced_tree=False, compact_nodes=False).query(
        positions, k=k + 1, distance_upper_bound=params.neighbor_dist
    )
    if (idx[:, 0] == np.arange(n)).all():  # self first (no other agent at distance 0)
        idx = idx[:, 1:]
    else:
        idx = np.where(idx == np.arange(n)[:, None], n, idx)  # drop self; n marks "none"
        idx = np.take_along_axis(idx, np.argsort(idx == n, axis=1, kind="stable"), axis=1)[:, :k]
    safe = np.minimum(idx, n - 1)
    d2 = (positions[safe, 0] - positions[:, None, 0]) ** 2 + (positions[safe, 1] - positions[:, None, 1]) ** 2
    d2[idx == n] = np.inf
    later, earlier = d2[:, 1:], d2[:, :-1]
    if ((later < earlier) | ((later == earlier) & (idx[:, 1:] < idx[:, :-1]))).any():  # ties: by index, as the twin
        order = np.lexsort((idx, d2), axis=1)
        idx, d2 = np.take_along_axis(idx, order, axis=1), np.take_along_axis(d2, order, axis=1)
    valid = d2 < range_sq
    return np.where(valid, idx, 0), valid


def _agent_lines(positions, velocities, radii, params: OrcaParams):
    """Agent half-planes: lines (4, K, N) -- px, py, dx, dy, slot first -- and their mask (K, N)."""
    idx, valid = _agent_neighbours(positions, params)
    idx, valid = np.ascontiguousarray(idx.T), np.ascontiguousarray(valid.T)
    state = np.concatenate([positions.T, velocities.T])  # (4, N): x, y, u, v
    rel = state[:, idx] - state[:, None, :]  # neighbour minus self, (4, K, N)
    rx, ry = rel[0], rel[1]
    vx, vy = -rel[2], -rel[3]  # relative velocity: self minus neighbour
    dist_sq = rx * rx + ry * ry
    r = radii + radii[idx]
    r_sq = r * r
    apart = dist_sq > r_sq
    # apart: w from the cut-off centre (rel_pos / tau) to the relative velocity; overlapping: from rel_pos / dt
    inv = np.where(apart, 1.0 / params.time_horizon, 1.0 / params.time_step)
    wx, wy = vx - inv * rx, vy - inv * ry
    w_sq = wx * wx + wy * wy
    dot = wx * rx + wy * ry
    circle = ~apart | ((dot < 0.0) & (dot * dot > r_sq * w_sq))
    with np.errstate(divide="ignore", invalid="ignore"):
        w_len = np.sqrt(w_sq)
        ux, uy = wx / w_len, wy / w_len
        leg = np.sqrt(dist_sq - r_sq)  # NaN where overlapping: the circle branch is taken there
        side = np.where(rx * wy - ry * wx > 0.0, 1.0, -1.0)  # +1: left leg, -1: right leg
        lx = side * ((rx * leg - side * ry * r) / dist_sq)
        ly = side * ((side * rx * r + ry * leg) / dist_sq)
    proj = vx * lx + vy * ly
    scale = r * inv - w_len
    px = state[2] + 0.5 * np.where(circle, scale * ux, proj * lx - vx)
    py = state[3] + 0.5 * np.where(circle, scale * uy, proj * ly - vy)
    return _fill(np.stack([px, py, np.where(circle, uy, lx), np.where(circle, -ux, ly)]), valid), valid


FILLER = np.array([0.0, -FAR, 1.0, 0.0])[:, None, None]  # (px, py, dx, dy) of the filler line


def _fill(lines, valid):
    """Lines (4, L, M) with unused slots replaced by the filler line, through (0, -FAR) along (1, 0):
    the whole max-speed disc satisfies it and it never bounds another line inside the disc."""
    return np.where(valid, lines, FILLER)


def _obstacle_neighbours(positions, radii, max_speeds, obs: ObstacleSet, params: OrcaParams):
    """Obstacle edges per agent (N, M) nearest first, ties in RVO2's tree-walk order, and a mask."""
    n = len(positions)
    a = obs.points[None]
    b = obs.points[obs.next][None]
    p = positions[:, None, :]
    side = _left_of(a, b, p)  # (N, V)
    ex, ey = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    qx, qy = p[..., 0] - a[..., 0], p[..., 1] - a[..., 1]
    s = (qx * ex + qy * ey) / (ex * ex + ey * ey)
    # distance to the closest point of the edge, as RVO2 writes it (equal corner distances tie exactly)
    cx = np.where(s < 0.0, a[..., 0], np.where(s > 1.0, b[..., 0], a[..., 0] + s * ex))
    cy = np.where(s < 0.0, a[..., 1], np.where(s > 1.0, b[..., 1], a[..., 1] + s * ey))
    d2 = (p[..., 0] - cx) ** 2 + (p[..., 1] - cy) ** 2
    reach = params.time_horizon_obst * max_speeds + radii
    sel = (side < 0.0) & (d2 < (reach * reach)[:, None])
    counts = sel.sum(1)
    m = int(counts.max()) if n else 0
    if m == 0:
        return np.zeros((n, 0), dtype=np.int64), np.zeros((n, 0), dtype=bool)
    rank = np.zeros(sel.shape, dtype=np.int64)
    ag, vx = np.nonzero(sel)
    rank[ag, vx] = _walk_rank(positions[ag], vx, obs)
    order = np.lexsort((rank, np.where(sel, d2, np.inf)), axis=1)[:, :m]
    return order, np.arange(m)[None, :] < counts[:, None]


def _walk_rank(pos: np.ndarray, v: np.ndarray, obs: ObstacleSet) -> np.ndarray:
    """Position of node v in the tree walk ``queryObstacleTreeRecursive`` makes from pos (pairs (P,))."""
    anc = obs.ancestors[v]  # (P, D)
    live = anc >= 0
    a = np.where(live, anc, 0)
    near_left = _left_of(obs.points[a], obs.points[obs.next[a]], pos[:, None, :]) >= 0.0
    near = np.where(near_left, obs.node_left[a], obs.node_right[a])
    near_size = np.where(near >= 0, obs.subtree[np.maximum(near, 0)], 0)
    skipped = np.where(live & (near_left != obs.in_left[v]), near_size + 1, 0).sum(1)
    own_left = _left_of(obs.points[v], obs.points[obs.next[v]], pos) >= 0.0
    own_near = np.where(own_left, obs.node_left[v], obs.node_right[v])
    return skipped + np.where(own_near >= 0, obs.subtree[np.maximum(own_near, 0)], 0)


def _normalised(x, y):
    length = np.sqrt(x * x + y * y)
    return x / length, y / length


def _tangents(rx, ry, r):
    """Left and right tangent (leg) directions from the agent to a circle of radius r at (rx, ry)."""
    d2 = rx * rx + ry * ry
    leg = np.sqrt(np.maximum(d2 - r * r, 0.0))
    left = ((rx * leg - ry * r) / d2, (rx * r + ry * leg) / d2)
    right = ((rx * leg + ry * r) / d2, (-rx * r + ry * leg) / d2)
    return left, right


def _obstacle_lines(positions, velocities, radii, max_speeds, obs: ObstacleSet, params: OrcaParams):
    """Obstacle half-planes: lines (4, M, N) and their mask (M, N), or None when no agent sees an edge.

    The first loop of ``computeNewVelocity``, for all (agent, edge) pairs at once; only the "already
    covered by an earlier line" test runs edge slot by edge slot.
    """
    o1, valid = _obstacle_neighbours(positions, radii, max_speeds, obs, params)
    if o1.shape[1] == 0:
        return None
    pts, dirs, cvx, prev, nxt = obs.points, obs.directions, obs.convex, obs.prev, obs.next
    inv = 1.0 / params.time_horizon_obst
    px0, py0 = positions[:, None, 0], positions[:, None, 1]
    vx, vy = velocities[:, None, 0], velocities[:, None, 1]
    r = radii[:, None]
    r_sq = r * r
    o2 = nxt[o1]
    r1x, r1y = pts[o1, 0] - px0, pts[o1, 1] - py0
    r2x, r2y = pts[o2, 0] - px0, pts[o2, 1] - py0
    with np.errstate(divide="ignore", invalid="ignore"):
        d1, d2 = r1x * r1x + r1y * r1y, r2x * r2x + r2y * r2y
        ovx, ovy = pts[o2, 0] - pts[o1, 0], pts[o2, 1] - pts[o1, 1]
        s = (-r1x * ovx - r1y * ovy) / (ovx * ovx + ovy * ovy)
        dline = (-r1x - s * ovx) ** 2 + (-r1y - s * ovy) ** 2
        # already touching a vertex or the edge: the line through the agent's velocity origin
        hit_left = (s < 0.0) & (d1 <= r_sq)
        hit_right = ~hit_left & (s > 1.0) & (d2 <= r_sq)
        hit_edge = (s >= 0.0) & (s <= 1.0) & (dline <= r_sq)
        hit = hit_left | hit_right | hit_edge
        emit_hit = (hit_left & cvx[o1]) | (hit_right & cvx[o2] & (r2x * dirs[o2, 1] - r2y * dirs[o2, 0] >= 0.0))
        emit_hit |= hit_edge
        hx, hy = _normalised(np.where(hit_left, -r1y, -r2y), np.where(hit_left, r1x, r2x))
        hx, hy = np.where(hit_edge, -dirs[o1, 0], hx), np.where(hit_edge, -dirs[o1, 1], hy)
        # no collision: legs; seen obliquely, both legs come from one vertex
        obl_left = ~hit & (s < 0.0) & (dline <= r_sq)
        obl_right = ~hit & (s > 1.0) & (dline <= r_sq)
        usual = ~hit & ~obl_left & ~obl_right
        emit_legs = ~hit & ~(obl_left & ~cvx[o1]) & ~(obl_right & ~cvx[o2])
        a1 = np.where(obl_right, o2, o1)
        a2 = np.where(obl_left, o1, o2)
        (llx, lly), _ = _tangents(np.where(obl_right, r2x, r1x), np.where(obl_right, r2y, r1y), r)
        _, (rlx, rly) = _tangents(np.where(obl_left, r1x, r2x), np.where(obl_left, r1y, r2y), r)
        flat_l, flat_r = usual & ~cvx[o1], usual & ~cvx[o2]  # non-convex vertex: leg extends the cut-off
        llx, lly = np.where(flat_l, -dirs[o1, 0], llx), np.where(flat_l, -dirs[o1, 1], lly)
        rlx, rly = np.where(flat_r, dirs[o1, 0], rlx), np.where(flat_r, dirs[o1, 1], rly)
        # a leg pointing into the neighbouring edge is replaced by that edge ("foreign" leg)
        nbx, nby = -dirs[prev[a1], 0], -dirs[prev[a1], 1]
        foreign_l = cvx[a1] & (llx * nby - lly * nbx >= 0.0)
        llx, lly = np.where(foreign_l, nbx, llx), np.where(foreign_l, nby, lly)
        foreign_r = cvx[a2] & (rlx * dirs[a2, 1] - rly * dirs[a2, 0] <= 0.0)
        rlx, rly = np.where(foreign_r, dirs[a2, 0], rlx), np.where(foreign_r, dirs[a2, 1], rly)
        lcx, lcy = inv * (pts[a1, 0] - px0), inv * (pts[a1, 1] - py0)
        rcx, rcy = inv * (pts[a2, 0] - px0), inv * (pts[a2, 1] - py0)
        cux, cuy = rcx - lcx, rcy - lcy
        same = a1 == a2
        t = np.where(same, 0.5, ((vx - lcx) * cux + (vy - lcy) * cuy) / (cux * cux + cuy * cuy))
        t_l = (vx - lcx) * llx + (vy - lcy) * lly
        t_r = (vx - rcx) * rlx + (vy - rcy) * rly
        on_lc = ((t < 0.0) & (t_l < 0.0)) | (same & (t_l < 0.0) & (t_r < 0.0))
        on_rc = ~on_lc & (t > 1.0) & (t_r < 0.0)
        ccx, ccy = np.where(on_lc, lcx, rcx), np.where(on_lc, lcy, rcy)
        ux, uy = _normalised(vx - ccx, vy - ccy)
        inf = np.inf
        d_cut = np.where((t < 0.0) | (t > 1.0) | same, inf, (vx - lcx - t * cux) ** 2 + (vy - lcy - t * cuy) ** 2)
        d_l = np.where(t_l < 0.0, inf, (vx - lcx - t_l * llx) ** 2 + (vy - lcy - t_l * lly) ** 2)
        d_r = np.where(t_r < 0.0, inf, (vx - rcx - t_r * rlx) ** 2 + (vy - rcy - t_r * rly) ** 2)
        cut = (d_cut <= d_l) & (d_cut <= d_r)
        use_l = ~cut & (d_l <= d_r)
        use_r = ~cut & ~use_l
        circ = on_lc | on_rc
        ldx = np.where(cut, -dirs[a1, 0], np.where(use_l, llx, -rlx))
        ldy = np.where(cut, -dirs[a1, 1], np.where(use_l, lly, -rly))
        bx, by = np.where(use_r, rcx, lcx), np.where(use_r, rcy, lcy)
        k = r * inv
        dx = np.where(hit, hx, np.where(circ, uy, ldx))
        dy = np.where(hit, hy, np.where(circ, -ux, ldy))
        px = np.where(hit, 0.0, np.where(circ, ccx + k * ux, bx + k * -ldy))
        py = np.where(hit, 0.0, np.where(circ, ccy + k * uy, by + k * ldx))
    emit_leg_line = circ | cut | (use_l & ~foreign_l) | (use_r & ~foreign_r)
    emits = valid & np.where(hit, emit_hit, emit_legs & emit_leg_line)
    # skip an edge whose velocity obstacle an earlier emitted line already covers (both cut-off centres)
    kr = inv * radii[:, None, None]
    c1 = (inv * r1x[:, None, :] - px[:, :, None]) * dy[:, :, None] - (inv * r1y[:, None, :] - py[:, :, None]) * dx[
        :, :, None
    ] - kr >= -EPS
    c2 = (inv * r2x[:, None, :] - px[:, :, None]) * dy[:, :, None] - (inv * r2y[:, None, :] - py[:, :, None]) * dx[
        :, :, None
    ] - kr >= -EPS
    covers = c1 & c2  # [n, j, k]: line j covers edge k
    emitted = emits.copy()
    for k_ in range(1, emitted.shape[1]):
        emitted[:, k_] &= ~(covers[:, :k_, k_] & emitted[:, :k_]).any(1)
    lines = _fill(np.stack([px, py, dx, dy]), emitted)  # (4, N, M)
    return np.ascontiguousarray(lines.transpose(0, 2, 1)), np.ascontiguousarray(emitted.T)


def _pairs(lines):
    """``linearProgram1``'s terms for every pair of lines, each (L_j, L_i, M) from lines (4, L, M).

    Line j cuts line i at ``p_i + t d_i``; it bounds t from above where det(d_i, d_j) > EPS, from
    below where it is < -EPS. Lines within ``EPS`` of parallel do not cut: ``bad`` marks those that
    exclude line i altogether. The other line j comes first, so reductions over it are fast.
    Returns ``(upper, lower, bad)``.
    """
    px, py, dx, dy = lines
    den = dx[None] * dy[:, None] - dy[None] * dx[:, None]  # [j, i]: det(d_i, d_j)
    num = dx[:, None] * py[None] - dy[:, None] * px[None]  # det(d_j, p_i - p_j) = det(d_j, p_i) - det(d_j, p_j)
    num -= (dx * py - dy * px)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    upper = np.where(den > EPS, t, np.inf)
    lower = np.where(den < -EPS, t, -np.inf)
    return upper, lower, (np.abs(den) <= EPS) & (num < 0.0)  # j == i: den == num == 0, never bad


def _disc(lines, radius):
    """Interval of each line inside the max-speed disc: ``(t_left, t_right, non-empty)``, each (L, M)."""
    px, py, dx, dy = lines
    dot = px * dx + py * dy
    disc = dot * dot + radius * radius - (px * px + py * py)
    sq = np.sqrt(np.maximum(disc, 0.0))
    return -sq - dot, sq - dot, disc >= 0.0


def _violation(lines, vx, vy):
    """det(d, p - v) of lines (4, ...): > 0 where velocity v breaks the half-plane (p, d)."""
    return lines[2] * (lines[1] - vy) - lines[3] * (lines[0] - vx)


def _clip_to_disc(ox, oy, radius):
    speed_sq = ox * ox + oy * oy
    outside = speed_sq > radius * radius
    norm = np.sqrt(np.where(outside, speed_sq, 1.0))
    return np.where(outside, ox / norm * radius, ox), np.where(outside, oy / norm * radius, oy)


def _closest(lines, t_left, t_right, ok, ox, oy):
    """Per agent, the point of the best feasible line interval closest to o; (M,) each."""
    px, py, dx, dy = lines
    t = np.clip(dx * (ox - px) + dy * (oy - py), t_left, t_right)
    cx, cy = px + t * dx, py + t * dy
    best = np.argmin(np.where(ok, (cx - ox) ** 2 + (cy - oy) ** 2, np.inf), axis=0)
    cols = np.arange(px.shape[1])
    return cx[best, cols], cy[best, cols]


def _lp2(lines, radius, ox, oy):
    """``linearProgram2`` (closest to o) for all agents, loop-free: ``(vx, vy, fail)`` each (N,).

    Lines are (4, L, N). The optimum is unique: o clipped to the disc if that breaks no line, else
    the point closest to o of some line's interval left by the disc and all other lines -- where
    RVO2's incremental LP ends too. Where that is empty, ``fail`` is the first line whose prefix of
    lines is infeasible (else L) and the answer the optimum of the prefix before it, as in RVO2.
    """
    n_lines, n = lines.shape[1:]
    v0x, v0y = _clip_to_disc(ox, oy, radius)
    fail = np.full(n, n_lines)
    if n_lines == 0:
        return v0x, v0y, fail
    con = np.flatnonzero((_violation(lines, v0x, v0y) > 0.0).any(axis=0))
    if len(con) == 0:
        return v0x, v0y, fail
    # o (clipped) breaks a line: the answer lies on one of the lines
    lines, radius, ox, oy = lines[..., con], radius[con], ox[con], oy[con]
    t_left0, t_right0, in_disc = _disc(lines, radius)
    upper, lower, bad = _pairs(lines)
    t_right = np.minimum(upper.min(axis=0), t_right0)
    t_left = np.maximum(lower.max(axis=0), t_left0)
    ok = in_disc & ~bad.any(axis=0) & (t_left <= t_right)
    vx, vy = v0x.copy(), v0y.copy()
    vx[con], vy[con] = _closest(lines, t_left, t_right, ok, ox, oy)
    rows = np.flatnonzero(~ok.any(axis=0))
    if len(rows) == 0:
        return vx, vy, fail
    # infeasible agents: line intervals within each prefix of lines 0..k (running min/max over k)
    upper, lower, bad = upper[:, :, rows], lower[:, :, rows], bad[:, :, rows]
    for k in range(1, n_lines):
        np.minimum(upper[k - 1], upper[k], out=upper[k])
        np.maximum(lower[k - 1], lower[k], out=lower[k])
        np.logical_or(bad[k - 1], bad[k], out=bad[k])
    t_right = np.minimum(upper, t_right0[:, rows]).swapaxes(0, 1)  # [i, k, row]
    t_left = np.maximum(lower, t_left0[:, rows]).swapaxes(0, 1)
    ok = in_disc[:, None, rows] & ~bad.swapaxes(0, 1) & (t_left <= t_right) & np.tri(n_lines, dtype=bool).T[:, :, None]
    lines, ox, oy = lines[..., rows], ox[rows], oy[rows]
    rows = con[rows]
    first_break = np.argmax(_violation(lines, v0x[rows], v0y[rows]) > 0.0, axis=0)
    feasible = (np.arange(n_lines)[:, None] < first_break) | ok.any(axis=0)  # [k, row]
    fail[rows] = np.argmin(feasible, axis=0)
    k = np.maximum(fail[rows] - 1, 0)
    cols = np.arange(len(rows))
    cx, cy = _closest(lines, t_left[:, k, cols], t_right[:, k, cols], ok[:, k, cols], ox, oy)
    use_v0 = fail[rows] <= first_break  # the prefix before the failing line keeps o (clipped)
    vx[rows] = np.where(use_v0, v0x[rows], cx)
    vy[rows] = np.where(use_v0, v0y[rows], cy)
    return vx, vy, fail


def _lp_direction(lines, radius, ox, oy):
    """``linearProgram2`` in direction mode (furthest along the unit vector o), loop-free.

    Lines are (4, L, M). The optimum is o * radius if that breaks no line, else the end along o of
    some line's interval left by the disc and all other lines. Returns ``(vx, vy, feasible)`` (M,).
    """
    v0x, v0y = ox * radius, oy * radius
    if lines.shape[1] == 0:
        return v0x, v0y, np.ones(len(v0x), dtype=bool)
    ok0 = (_violation(lines, v0x, v0y) <= 0.0).all(axis=0)
    t_left, t_right, ok = _disc(lines, radius)
    upper, lower, bad = _pairs(lines)
    t_right = np.minimum(upper.min(axis=0), t_right)
    t_left = np.maximum(lower.max(axis=0), t_left)
    ok &= ~bad.any(axis=0) & (t_left <= t_right)
    px, py, dx, dy = lines
    t = np.where(ox * dx + oy * dy > 0.0, t_right, t_left)
    cx, cy = px + t * dx, py + t * dy
    best = np.argmax(np.where(ok, cx * ox + cy * oy, -np.inf), axis=0)
    cols = np.arange(px.shape[1])
    return np.where(ok0, v0x, cx[best, cols]), np.where(ok0, v0y, cy[best, cols]), ok0 | ok.any(axis=0)


def _lp3(lines, projectable, n_obst, begin, radius, vx, vy):
    """``linearProgram3`` for agents whose 2-D LP failed at line ``begin`` (r,), all together.

    Lines are (4, L, r). RVO2 walks the lines from ``begin``; at each line i broken by more than the
    best so far, it keeps obstacle lines (slots < n_obst) hard, replaces each agent line j < i by the
    line where breaking j and i costs the same, and takes the velocity furthest into line i. Here
    every agent jumps straight to its next such line, so the loop runs as many times as the longest
    such chain (a few), each time one direction-optimising 2-D LP for all agents still going.
    ``projectable`` (L, r) marks agent slots that hold real lines.
    """
    n_lines, r = lines.shape[1:]
    slot = np.arange(n_lines)[:, None]
    done = np.full(r, -1)  # last line handled
    distance = np.zeros(r)
    while True:
        todo = (slot > done) & (slot >= begin) & (_violation(lines, vx, vy) > distance)
        rows = np.flatnonzero(todo.any(axis=0))
        if len(rows) == 0:
            return vx, vy
        i = np.argmax(todo[:, rows], axis=0)
        line_i = lines[:, i, rows]  # (4, rows)
        pix, piy, dix, diy = line_i
        width = max(int(i.max()), n_obst)  # later slots would all be fillers
        others = lines[:, :width, rows]
        pjx, pjy, djx, djy = others
        det = dix * djy - diy * djx
        par = np.abs(det) <= EPS
        use = projectable[:width, rows] & (slot[:width] < i) & ~(par & (dix * djx + diy * djy > 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (djx * (piy - pjy) - djy * (pix - pjx)) / det
            ex, ey = _normalised(djx - dix, djy - diy)
        qx = np.where(par, 0.5 * (pix + pjx), pix + s * dix)
        qy = np.where(par, 0.5 * (piy + pjy), piy + s * diy)
        proj = np.stack([qx, qy, ex, ey])
        if n_obst:  # obstacle lines stay as they are
            hard = slot[:width] < n_obst
            proj = np.where(hard, others, proj)
            use |= hard
        nx, ny, ok = _lp_direction(_fill(proj, use), radius[rows], -diy, dix)
        vx[rows] = np.where(ok, nx, vx[rows])
        vy[rows] = np.where(ok, ny, vy[rows])
        distance[rows] = _violation(line_i, vx[rows], vy[rows])
        done[rows] = i


def orca_step(
    positions: np.ndarray,
    velocities: np.ndarray,
    pref_velocities: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    obstacles: ObstacleSet | None,
    params: OrcaParams,
) -> np.ndarray:
    """New velocities of all agents for one step (RVO2's ``computeNeighbors`` + ``computeNewVelocity``).

    Args:
        positions: (N, 2) float64, m.
        velocities: (N, 2) float64, m/s, the current velocities.
        pref_velocities: (N, 2) float64, m/s, where each agent wants to go.
        radii: (N,) float64, m.
        max_speeds: (N,) float64, m/s.
        obstacles: from :func:`build_obstacles`, or None.
        params: shared ORCA parameters.

    Returns:
        (N, 2) float64 new velocities, m/s; the caller moves the agents (p += v dt, as RVO2).
    """
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    vel = np.asarray(velocities, dtype=np.float64).reshape(-1, 2)
    pref = np.asarray(pref_velocities, dtype=np.float64).reshape(-1, 2)
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(pos),))
    speeds = np.broadcast_to(np.asarray(max_speeds, dtype=np.float64), (len(pos),))
    if not len(vel) == len(pref) == len(pos):
        raise ValueError("orca_step: positions, velocities and pref_velocities must all be (N, 2)")
    lines, real, n_obst = _lines(pos, vel, radii, speeds, obstacles, params)
    vx, vy, fail = _lp2(lines, speeds, pref[:, 0], pref[:, 1])
    bad = np.flatnonzero(fail < lines.shape[1])
    if len(bad):
        projectable = real[:, bad] & (np.arange(lines.shape[1]) >= n_obst)[:, None]
        vx[bad], vy[bad] = _lp3(lines[..., bad], projectable, n_obst, fail[bad], speeds[bad], vx[bad], vy[bad])
    return np.stack([vx, vy], axis=1)


def orca_lines(positions, velocities, radii, max_speeds, obstacles: ObstacleSet | None, params: OrcaParams):
    """All ORCA half-planes of all agents, in RVO2's order (obstacle lines, then agent lines).

    A velocity v is allowed by line (p, d) when det(d, p - v) <= 0 (v on the left of d). Arguments
    as :func:`orca_step`.

    Returns:
        ``(px, py, dx, dy, real, n_obst)``: (N, L) float64 points (m/s) and unit directions, (N, L)
        bool marking slots that hold a line (the others hold an always-satisfied filler), and the
        number of obstacle slots (they come first).
    """
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    vel = np.asarray(velocities, dtype=np.float64).reshape(-1, 2)
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(pos),))
    speeds = np.broadcast_to(np.asarray(max_speeds, dtype=np.float64), (len(pos),))
    lines, real, n_obst = _lines(pos, vel, radii, speeds, obstacles, params)
    return (*lines.transpose(0, 2, 1), real.T, n_obst)


def _lines(pos, vel, radii, speeds, obstacles: ObstacleSet | None, params: OrcaParams):
    """:func:`orca_lines` as the LPs use them: lines (4, L, N), mask (L, N), number of obstacle slots."""
    lines, valid = _agent_lines(pos, vel, radii, params)
    obst = None
    if obstacles is not None and obstacles.n_vertices and len(pos):
        obst = _obstacle_lines(pos, vel, radii, speeds, obstacles, params)
    if obst is None:
        return lines, valid, 0
    return np.concatenate([obst[0], lines], axis=1), np.concatenate([obst[1], valid]), obst[0].shape[1]
