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

Modules, split as Recast and Detour split theirs: :mod:`~song.geometry.navmesh.build` (grid → mesh),
:mod:`~song.geometry.navmesh.mesh` (the data and its build parameters), :mod:`~song.geometry.navmesh.query`
(queries with statuses), :mod:`~song.geometry.navmesh.carve` (ORCA's walls, temporary obstacles) and
:mod:`~song.geometry.navmesh.io` (arrays in and out).
"""

from song.geometry.navmesh.build import (
    OFFSET_SLACK_M,
    T_JUNCTION_M,
    NavmeshBuildError,
    _adjacency,
    _reflex,
    _triangulate,
    _visibility_edges,
    build_navmesh,
    check_on_legal_cells,
    navmesh_from_polygons,
    simplify_polygons,
    trace_legal,
)
from song.geometry.navmesh.carve import CARVINGS_KEPT, _component_rings, carve_discs, obstacle_rings
from song.geometry.navmesh.io import navmesh_arrays, navmesh_from_arrays
from song.geometry.navmesh.mesh import BUCKET_M, NAVMESH_FORMAT, Navmesh, NavmeshParams, _ring_links
from song.geometry.navmesh.query import PathResult, PathStatus, _cross, funnel, polyline_length

__all__ = [
    "BUCKET_M",
    "CARVINGS_KEPT",
    "NAVMESH_FORMAT",
    "OFFSET_SLACK_M",
    "T_JUNCTION_M",
    "Navmesh",
    "NavmeshBuildError",
    "NavmeshParams",
    "PathResult",
    "PathStatus",
    "_adjacency",
    "_component_rings",
    "_cross",
    "_reflex",
    "_ring_links",
    "_triangulate",
    "_visibility_edges",
    "build_navmesh",
    "carve_discs",
    "check_on_legal_cells",
    "funnel",
    "navmesh_arrays",
    "navmesh_from_arrays",
    "navmesh_from_polygons",
    "obstacle_rings",
    "polyline_length",
    "simplify_polygons",
    "trace_legal",
]
