"""Recast's build: legal cells → contours → polygons → triangles, parts and the visibility graph.

Adjacency, connected parts, reflex vertices and the bitangent visibility graph follow the
triangulation; last, the invariant that the mesh covers no occupied cell is checked.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from song.geometry import _navmesh_kernel as _k
from song.geometry._navmesh_kernel import TOUCH_EPS
from song.geometry.navmesh.mesh import Navmesh, NavmeshParams, _ring_links
from song.geometry.navmesh.query import _cross

OFFSET_SLACK_M = 1e-4  # added to the inward offset: a strip exactly twice the offset wide must vanish, not
# collapse into a zero-width bridge between two parts (at ε = 1 cell, one-cell strips are that wide)
T_JUNCTION_M = 1e-9  # a vertex this close to the inside of a triangle edge splits the edge (see _triangulate)


class NavmeshBuildError(ValueError):
    """The build produced a mesh that breaks an invariant (it is never returned)."""


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
