"""Changing a built mesh: ORCA's walls grown back from it, and discs carved out (Detour's temporary obstacles)."""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from song.geometry.navmesh.build import navmesh_from_polygons
from song.geometry.navmesh.mesh import Navmesh

CARVINGS_KEPT = 256  # carvings a mesh remembers (:func:`carve_discs`; ~0.2 MB each with their query arrays)


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
