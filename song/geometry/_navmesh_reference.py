"""Plain references for the navmesh path queries (used by tests and benchmarks only).

* :func:`visibility_path_reference`: the reduced visibility graph searched as the compiled query does,
  written with vectorised numpy and scipy's Dijkstra (the implementation the compiled kernel replaced;
  its twin in tests and benchmarks).
* :func:`shortest_path_reference`: the full visibility graph over every mesh vertex, each edge checked
  with shapely's exact ``covers`` and searched with networkx — obviously correct, slow.
* :func:`grid_path_length`: any-direction 16-connected shortest path on a fine grid of points inside
  the mesh — an independent upper bound on the true shortest path (up to the grid's ~2.7 % error).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from song.geometry._navmesh_kernel import TOUCH_EPS
from song.geometry.navmesh import Navmesh, _component_rings, _cross, _ring_links

STEPS_16 = [(1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2)]


def points_on_mesh(mesh: Navmesh, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) points drawn uniformly over the mesh's area (for tests and benchmarks)."""
    t = mesh.vertices[mesh.triangles]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    k = rng.choice(len(t), n, p=area / area.sum())
    u, v = rng.random((2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return t[k, 0] + u[:, None] * e1[k] + v[:, None] * e2[k]


def segments_blocked(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether query segments p→q hit wall segments a→b (the kernel's ``_blocked``, vectorised).

    Args:
        p: (..., 2) float64 query segment starts, m.
        q: (..., 2) float64 query segment ends, m.
        a: (..., 2) float64 wall segment starts, m (broadcast against p, q).
        b: (..., 2) float64 wall segment ends, m.

    Returns:
        (...) bool: a crossing, or a wall end touching the segment's inside. A segment end on the
        wall and collinear overlaps do not count (a path may start on or run along a wall).
    """
    dx, dy = q[..., 0] - p[..., 0], q[..., 1] - p[..., 1]
    ex, ey = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    o1 = _cross(dx, dy, a[..., 0] - p[..., 0], a[..., 1] - p[..., 1])
    o2 = _cross(dx, dy, b[..., 0] - p[..., 0], b[..., 1] - p[..., 1])
    o3 = _cross(ex, ey, p[..., 0] - a[..., 0], p[..., 1] - a[..., 1])
    o4 = _cross(ex, ey, q[..., 0] - a[..., 0], q[..., 1] - a[..., 1])
    o1, o2, o3, o4 = (np.where(np.abs(o) < TOUCH_EPS, 0.0, o) for o in (o1, o2, o3, o4))
    collinear = (o1 == 0.0) & (o2 == 0.0)
    return (o1 * o2 <= 0.0) & (o3 * o4 < 0.0) & ~collinear


def segment_clear_reference(mesh: Navmesh, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N,) bool: segments p→q hit no boundary segment."""
    p, q = np.atleast_2d(p).astype(np.float64), np.atleast_2d(q).astype(np.float64)
    hit = segments_blocked(p[:, None], q[:, None], mesh.seg_a[None], mesh.seg_b[None])
    return ~hit.any(axis=1)


def tangent_reference(mesh: Navmesh, vids: np.ndarray, other: np.ndarray) -> np.ndarray:
    """(N,) bool: the line from boundary vertex ``vids`` to ``other`` (N, 2) leaves both its walls on one side."""
    prev, nxt = _ring_links(len(mesh.vertices), mesh.segments)
    v = mesh.vertices[vids]
    d = other - v
    s1 = _cross(*d.T, *(mesh.vertices[prev[vids]] - v).T)
    s2 = _cross(*d.T, *(mesh.vertices[nxt[vids]] - v).T)
    s1[np.abs(s1) < TOUCH_EPS] = 0.0
    s2[np.abs(s2) < TOUCH_EPS] = 0.0
    return s1 * s2 >= 0.0


def visibility_edges_reference(mesh: Navmesh) -> np.ndarray:
    """(E, 2) bitangent visible reflex pairs (i < j), every pair tested against every wall."""
    i, j = np.triu_indices(len(mesh.reflex), k=1)
    vi, vj = mesh.reflex[i], mesh.reflex[j]
    ok = tangent_reference(mesh, vi, mesh.vertices[vj]) & tangent_reference(mesh, vj, mesh.vertices[vi])
    i, j = i[ok], j[ok]
    clear = segment_clear_reference(mesh, mesh.vertices[mesh.reflex[i]], mesh.vertices[mesh.reflex[j]])
    return np.stack([i[clear], j[clear]], -1).astype(np.int64)


def visibility_path_reference(mesh: Navmesh, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
    """The shortest path (K, 2) between two points of one mesh part over the reduced visibility graph."""
    start, goal = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
    if segment_clear_reference(mesh, start[None], goal[None])[0]:
        return np.array([start, goal])
    r = len(mesh.reflex)
    v = mesh.vertices[mesh.reflex]

    def visible(point):
        idx = np.flatnonzero(tangent_reference(mesh, mesh.reflex, np.broadcast_to(point, v.shape)))
        idx = idx[segment_clear_reference(mesh, np.broadcast_to(point, (len(idx), 2)), v[idx])]
        return idx, np.linalg.norm(v[idx] - point, axis=1)

    si, sd = visible(start)
    gi, gd = visible(goal)
    e = visibility_edges_reference(mesh)
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
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
    return np.vstack([start, v[nodes], goal])


def mesh_polygons(mesh: Navmesh):
    """The mesh's polygons (shapely), one per connected boundary region."""
    from shapely.geometry import Polygon

    return [Polygon(rings[0], rings[1:]) for rings in _component_rings(mesh)]


def shortest_path_reference(mesh: Navmesh, start: np.ndarray, goal: np.ndarray) -> float:
    """Length (m) of the shortest path inside the mesh between two points on it (inf if none)."""
    import networkx as nx
    import shapely
    from shapely.geometry import LineString

    region = shapely.union_all(mesh_polygons(mesh)).buffer(1e-9)
    pts = np.vstack([start, goal, mesh.vertices])
    graph = nx.Graph()
    for i in range(len(pts)):
        for j in range(i + 1, len(pts)):
            if region.covers(LineString([pts[i], pts[j]])):
                graph.add_edge(i, j, weight=float(np.linalg.norm(pts[i] - pts[j])))
    try:
        return float(nx.dijkstra_path_length(graph, 0, 1))
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        return float("inf")


def grid_path_length(mesh: Navmesh, start: np.ndarray, goal: np.ndarray, cell: float = 0.05) -> float:
    """16-connected grid shortest path (m) through points inside the mesh, from start to goal.

    Grid points are cell centres inside the mesh; an edge is kept when its end points and the
    points every quarter cell along it are inside the mesh. Start and goal join their nearest grid
    point by a straight segment.
    """
    import shapely

    region = shapely.union_all(mesh_polygons(mesh))
    shapely.prepare(region)

    def on_mesh(xy: np.ndarray) -> np.ndarray:
        return shapely.contains_xy(region, xy[:, 0], xy[:, 1])

    lo = mesh.vertices.min(axis=0)
    shape = np.ceil((mesh.vertices.max(axis=0) - lo) / cell).astype(int) + 1
    jj, ii = np.meshgrid(np.arange(shape[1]), np.arange(shape[0]))
    centres = lo + (np.stack([ii, jj], -1).reshape(-1, 2) + 0.5) * cell
    inside = on_mesh(centres).reshape(shape)
    index = np.full(shape, -1)
    index[inside] = np.arange(inside.sum())
    rows, cols, weights = [], [], []
    for di, dj in STEPS_16:
        i0, j0 = np.nonzero(inside)
        i1, j1 = i0 + di, j0 + dj
        ok = (i1 >= 0) & (i1 < shape[0]) & (j1 >= 0) & (j1 < shape[1])
        i0, j0, i1, j1 = i0[ok], j0[ok], i1[ok], j1[ok]
        ok = inside[i1, j1]
        i0, j0, i1, j1 = i0[ok], j0[ok], i1[ok], j1[ok]
        a = lo + (np.stack([i0, j0], -1) + 0.5) * cell
        b = lo + (np.stack([i1, j1], -1) + 0.5) * cell
        for t in (0.25, 0.5, 0.75):
            keep = on_mesh(a + (b - a) * t)
            i0, j0, i1, j1, a, b = i0[keep], j0[keep], i1[keep], j1[keep], a[keep], b[keep]
        rows.append(index[i0, j0])
        cols.append(index[i1, j1])
        weights.append(np.full(len(i0), cell * np.hypot(di, dj)))
    n = int(inside.sum())
    rows, cols, weights = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
    graph = sparse.csr_matrix((np.concatenate([weights, weights]), (np.r_[rows, cols], np.r_[cols, rows])), (n, n))
    pts = centres[inside.ravel()]
    s = int(np.argmin(((pts - start) ** 2).sum(1)))
    g = int(np.argmin(((pts - goal) ** 2).sum(1)))
    dist = csgraph.dijkstra(graph, directed=True, indices=s)
    return float(np.linalg.norm(pts[s] - start) + dist[g] + np.linalg.norm(pts[g] - goal))
