"""Closed triangle meshes of a :class:`~song.datasets.scenes.dressing.Dressing` for the USD proxy.

Walls are the traced wall polygons extruded from the floor to the ceiling (holes kept, earcut caps);
box parts are 8-point prisms, cylinders 16-sided prisms, ellipsoids 8 × 6 UV spheres -- every solid
closed with outward faces. The floor and the ceiling are flat meshes over the floor polygons (normals
up and down). The same dressing gives the Gaussians, so the two agree.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from song.datasets.scenes.dressing import Dressing
from song.datasets.scenes.furniture import Part
from song.datasets.scenes.usd import PRISM_FACES, ProxyMesh

CYLINDER_SIDES = 16
SPHERE_RINGS, SPHERE_SEGMENTS = 6, 8


def _earcut(polygon) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 2), triangles (T, 3) CCW) of a shapely polygon with holes."""
    import mapbox_earcut

    rings = [np.asarray(polygon.exterior.coords)[:-1]] + [np.asarray(r.coords)[:-1] for r in polygon.interiors]
    vertices = np.vstack(rings)
    ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
    tris = mapbox_earcut.triangulate_float64(vertices, ends).reshape(-1, 3).astype(np.int64)
    t = vertices[tris]
    area = (t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0])
    tris[area < 0] = tris[area < 0][:, ::-1]
    return vertices, tris


def extrude(name: str, polygon, z0: float, z1: float) -> ProxyMesh:
    """A closed prism over a shapely polygon (exterior CCW, holes CW), outward faces."""
    xy, caps = _earcut(polygon)
    n = len(xy)
    vertices = np.vstack([np.column_stack([xy, np.full(n, z0)]), np.column_stack([xy, np.full(n, z1)])])
    faces = [caps[:, ::-1], caps + n]  # bottom faces down, top faces up
    start = 0
    for ring in [polygon.exterior, *polygon.interiors]:
        k = len(ring.coords) - 1
        a = start + np.arange(k)
        b = start + (np.arange(k) + 1) % k
        faces += [np.column_stack([a, b, b + n]), np.column_stack([a, b + n, a + n])]
        start += k
    return ProxyMesh(name, vertices, np.vstack(faces))


def flat(name: str, polygon, z: float, up: bool) -> ProxyMesh:
    """A flat mesh over a polygon at height ``z``, its normal up or down."""
    xy, tris = _earcut(polygon)
    return ProxyMesh(name, np.column_stack([xy, np.full(len(xy), z)]), tris if up else tris[:, ::-1])


def _labelled(mesh: ProxyMesh, material: str | None, label: str | None, convex: bool = False) -> ProxyMesh:
    return dataclasses.replace(mesh, material=material, label=label, convex=convex)


def part_mesh(part: Part) -> ProxyMesh:
    """The closed mesh of one part."""
    c, s = math.cos(part.yaw), math.sin(part.yaw)
    rx, ry = part.half
    if part.kind == "box":
        local = np.array([[-rx, -ry], [rx, -ry], [rx, ry], [-rx, ry]])
        fp = np.column_stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]]) + part.centre
        vertices = np.vstack([np.column_stack([fp, np.full(4, part.z0)]), np.column_stack([fp, np.full(4, part.z1)])])
        return ProxyMesh(part.name, vertices, PRISM_FACES.copy())
    if part.kind == "cylinder":
        a = np.arange(CYLINDER_SIDES) * 2 * math.pi / CYLINDER_SIDES
        ring = np.column_stack([part.centre[0] + rx * np.cos(a), part.centre[1] + ry * np.sin(a)])
        from shapely.geometry import Polygon

        return extrude(part.name, Polygon(ring), part.z0, part.z1)
    rz, zc = (part.z1 - part.z0) / 2, (part.z0 + part.z1) / 2  # ellipsoid: a UV sphere
    polar = np.arange(1, SPHERE_RINGS) * math.pi / SPHERE_RINGS
    azim = np.arange(SPHERE_SEGMENTS) * 2 * math.pi / SPHERE_SEGMENTS
    pp, aa = np.meshgrid(polar, azim, indexing="ij")
    body = np.column_stack(
        [
            part.centre[0] + rx * (np.sin(pp) * np.cos(aa)).ravel(),
            part.centre[1] + ry * (np.sin(pp) * np.sin(aa)).ravel(),
            zc + rz * np.cos(pp).ravel(),
        ]
    )
    top, bottom = len(body), len(body) + 1
    vertices = np.vstack([body, [[*part.centre, part.z1], [*part.centre, part.z0]]])
    faces = []
    m = SPHERE_SEGMENTS
    for j in range(m):
        k = (j + 1) % m
        faces.append([top, j, k])
        last = (SPHERE_RINGS - 2) * m
        faces.append([bottom, last + k, last + j])
        for i in range(SPHERE_RINGS - 2):
            a, b, c2, d = i * m + j, i * m + k, (i + 1) * m + k, (i + 1) * m + j
            faces += [[a, d, c2], [a, c2, b]]
    return ProxyMesh(part.name, vertices, np.array(faces, dtype=np.int64))


GROUP_LABELS = {"lintel": "door_frame", "frame": "door_frame", "door": "door"}


def dressing_meshes(
    dressing: Dressing, categories: dict[str, str] | None = None
) -> tuple[list[ProxyMesh], list[ProxyMesh]]:
    """``(solids, surfaces)``: walls and parts (obstacles); floor, ceiling and entrance doors (seen only).

    Each mesh carries its material and semantic class: ``wall``, ``floor``, ``ceiling``, ``door``,
    ``door_frame``, or the category of the object a part belongs to (``categories``: object id →
    category, the semantic map's); parts are convex, walls are not.
    """
    from song.geometry.navmesh import trace_legal

    categories = categories or {}
    solids = [
        _labelled(extrude(f"wall_{k}", poly, 0.0, dressing.ceiling_height), dressing.wall_material, "wall")
        for k, poly in enumerate(dressing.walls)
    ]

    def labelled_part(part: Part) -> ProxyMesh:
        label = GROUP_LABELS.get(part.group) or categories.get(part.group)
        if part.group.startswith("item:"):
            label = part.group.split(":", 1)[1]
        return _labelled(part_mesh(part), part.material, label, convex=True)

    solids += [labelled_part(part) for part in dressing.parts if part.group != "door"]
    grid = dressing.grid
    surfaces = [labelled_part(part) for part in dressing.parts if part.group == "door"]
    for k, poly in enumerate(trace_legal(dressing.floor_mask, grid.resolution, grid.origin)):
        from shapely.geometry.polygon import orient

        poly = orient(poly.simplify(0.5 * grid.resolution, preserve_topology=True), 1.0)
        if poly.geom_type != "Polygon" or poly.area <= grid.resolution**2:
            continue
        surfaces += [
            _labelled(flat(f"floor_{k}_{j}", piece, 0.0, True), material, "floor")
            for j, (piece, material) in enumerate(_floor_pieces(dressing, poly))
        ]
        surfaces.append(_labelled(flat(f"ceiling_{k}", poly, dressing.ceiling_height, False), "ceiling", "ceiling"))
    return solids, surfaces


def _floor_pieces(dressing: Dressing, poly) -> list[tuple[object, str]]:
    """``poly`` cut by the regions: (piece, floor material) with the material the Gaussians use there."""
    from shapely.geometry.polygon import orient

    pieces, rest = [], poly
    for region, material in dressing.regions:
        if rest.is_empty:
            break
        pieces.append((rest.intersection(region), material))
        rest = rest.difference(region)
    pieces.append((rest, dressing.default_floor))
    out = []
    for shape, material in pieces:
        for part in getattr(shape, "geoms", [shape]):
            if part.geom_type == "Polygon" and part.area > 1e-4:
                out.append((orient(part, 1.0), material))
    return out


def room_meshes(semantic_map) -> list[ProxyMesh]:
    """One flat mesh per region of a semantic map, labelled with the region's type."""
    from shapely.geometry import Polygon
    from shapely.geometry.polygon import orient

    rooms = []
    for region in semantic_map.regions:
        polygon = orient(Polygon(region.polygon), 1.0)
        if polygon.is_valid and polygon.area > 0:
            rooms.append(_labelled(flat(f"room_{region.id}", polygon, 0.0, True), None, region.type))
    return rooms
