"""Plain references for the navmesh path queries (used by tests and benchmarks only).

* :func:`shortest_path_reference`: the full visibility graph over every mesh vertex, each edge checked
  with shapely's exact ``covers`` and searched with networkx — obviously correct, slow.
* :func:`grid_path_length`: any-direction 16-connected shortest path on a fine grid of points inside
  the mesh — an independent upper bound on the true shortest path (up to the grid's ~2.7 % error).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from song.geometry.navmesh import Navmesh, _component_rings

STEPS_16 = [(1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2)]


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
