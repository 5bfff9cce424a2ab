"""Navmesh geometry: funnel and exact paths on random polygons, statuses, snapping, moves, walls."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Polygon
from shapely.geometry.polygon import orient

from song.geometry._navmesh_reference import shortest_path_reference
from song.geometry.navmesh import (
    Navmesh,
    NavmeshParams,
    build_navmesh,
    funnel,
    navmesh_arrays,
    navmesh_from_arrays,
    navmesh_from_polygons,
    obstacle_rings,
    polyline_length,
)

PARAMS = NavmeshParams(0.25, 0.05, (0.0, 0.0), (1, 1), 0.05)


def star(seed: int, n: int) -> Polygon:
    """A random simple polygon: star-shaped around the origin."""
    rng = np.random.default_rng(seed)
    angles = np.sort(rng.uniform(0, 2 * np.pi - 0.3, n))
    angles += np.linspace(0, 0.2, n)  # keep them distinct
    radii = rng.uniform(0.3, 2.0, n)
    return orient(Polygon(np.stack([radii * np.cos(angles), radii * np.sin(angles)], -1)), 1.0)


def inside_points(poly: Polygon, seed: int, k: int) -> np.ndarray:
    rng = np.random.default_rng(seed + 1)
    lo, hi = np.array(poly.bounds[:2]), np.array(poly.bounds[2:])
    pts = rng.uniform(lo, hi, (400, 2))
    return pts[shapely.contains_xy(poly, pts[:, 0], pts[:, 1])][:k]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3, 14))
def test_funnel_in_simple_polygons_is_exact(seed: int, n: int) -> None:
    poly = star(seed, n)
    assume(poly.is_valid)
    mesh = navmesh_from_polygons([poly], PARAMS)
    pts = inside_points(poly, seed, 2)
    if len(pts) < 2:
        return
    a, b = pts
    ta, tb = mesh.locate(np.array([a, b]))
    tris = mesh.corridor(int(ta), int(tb), a, b)
    path = mesh.funnel_path(tris, a, b)
    # endpoints exact, inside the polygon, never shorter than the straight line
    assert np.array_equal(path[0], a) and np.array_equal(path[-1], b)
    assert poly.buffer(1e-9).covers(LineString(path))
    assert polyline_length(path) >= np.linalg.norm(b - a) - 1e-12
    # a simple polygon has one corridor, so the funnel is the true shortest path (and the exact query agrees)
    exact = mesh.find_path(a, b)
    reference = shortest_path_reference(mesh, a, b)
    assert polyline_length(path) == pytest.approx(reference, abs=1e-9)
    assert exact.status == "ok" and exact.length == pytest.approx(reference, abs=1e-9)


def test_funnel_straight_and_around_a_corner() -> None:
    # an L-shaped corridor: the path bends exactly at the inner corner (1, 1)
    poly = orient(Polygon([(0, 0), (3, 0), (3, 1), (1, 1), (1, 3), (0, 3)]), 1.0)
    mesh = navmesh_from_polygons([poly], PARAMS)
    res = mesh.find_path(np.array([2.5, 0.5]), np.array([0.5, 2.5]))
    assert res.status == "ok"
    np.testing.assert_allclose(res.points, [[2.5, 0.5], [1, 1], [0.5, 2.5]], atol=1e-12)
    assert funnel(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(2), np.ones(2)).shape == (2, 2)


def _holes_mesh() -> tuple[Navmesh, Polygon]:
    outer = [(0, 0), (10, 0), (10, 6), (0, 6)]
    holes = [[(2, 1), (3, 1), (3, 5), (2, 5)], [(5, 0.5), (6, 0.5), (6, 2.8), (5, 2.8)], [(5, 3.2), (6, 3.2), (6, 6.5)]]
    poly = orient(Polygon(outer, [h for h in holes[:2]]).difference(Polygon(holes[2])), 1.0)
    return navmesh_from_polygons([poly], PARAMS), poly


def test_exact_path_beats_corridor_choice_with_holes() -> None:
    mesh, poly = _holes_mesh()
    rng = np.random.default_rng(3)
    for a, b in inside_points(poly, 7, 16).reshape(-1, 2, 2):
        res = mesh.find_path(a, b)
        assert res.status == "ok"
        assert poly.buffer(1e-9).covers(LineString(res.points))
        assert res.length == pytest.approx(shortest_path_reference(mesh, a, b), abs=1e-9)
        ta, tb = mesh.locate(np.array([a, b]))
        pulled = mesh.funnel_path(mesh.corridor(int(ta), int(tb), a, b), a, b)
        assert res.length <= polyline_length(pulled) + 1e-9  # Detour's corridor can be longer; ours never is
    assert rng is not None


def test_statuses_never_raise() -> None:
    a = orient(Polygon([(0, 0), (2, 0), (2, 2), (0, 2)]), 1.0)
    b = orient(Polygon([(4, 0), (6, 0), (6, 2), (4, 2)]), 1.0)
    mesh = navmesh_from_polygons([a, b], PARAMS)
    assert mesh.component.max() == 1
    res = mesh.find_path(np.array([1.0, 1.0]), np.array([5.0, 1.0]))
    assert res.status == "partial" and res.reason
    np.testing.assert_allclose(res.points[-1], [2.0, 1.0], atol=1e-5)  # the reachable point nearest the goal
    res = mesh.find_path(np.array([1.0, 1.0]), np.array([5.0, 1.0]), allow_partial=False)
    assert res.status == "unreachable" and res.points.shape == (0, 2) and res.length == np.inf
    res = mesh.find_path(np.array([1.0, 1.0]), np.array([3.0, 9.0]))
    assert res.status == "off_mesh" and "goal" in res.reason
    res = mesh.find_path(np.array([2.3, 1.0]), np.array([0.5, 0.5]), max_snap=0.5)  # snapped start
    assert res.status == "ok" and res.points[0, 0] < 2.0 and mesh.contains(res.points).all()
    res = mesh.find_path(np.array([1.0, 1.0]), np.array([1.0, 1.0]))
    assert res.status == "ok" and res.length == 0.0


def test_constrained_moves_stay_on_mesh() -> None:
    mesh, poly = _holes_mesh()
    rng = np.random.default_rng(0)
    pos = inside_points(poly, 11, 200)
    for _ in range(30):
        target = pos + rng.normal(0, 0.05, pos.shape)
        pos = mesh.constrain_moves(pos, target)
        assert mesh.contains(pos, tol=1e-9).all()


def test_build_from_grid_round_trip_and_walls() -> None:
    # a 6 × 4 m room with a pillar, eroded by 0.25 m on a 0.05 m grid
    res, r = 0.05, 0.25
    free = np.ones((80, 120), dtype=bool)
    free[:2], free[-2:], free[:, :2], free[:, -2:] = False, False, False, False
    free[30:50, 50:70] = False
    from scipy import ndimage

    legal = ndimage.distance_transform_edt(free) * res >= r + 0.5 * res
    mesh = build_navmesh(legal, res, (0.0, 0.0), r, 0.05)
    assert mesh.component.max() == 0 and len(mesh.vertices) - len(mesh.reflex) == 4  # the room's corners
    pillar = mesh.vertices[mesh.reflex]  # the pillar's x in [2.5, 3.5], y in [1.5, 2.5], grown by r
    assert (np.abs(pillar - [3.0, 2.0]) <= 0.5 + r + 0.05).all()
    again = navmesh_from_arrays(navmesh_arrays(mesh))
    for name, value in navmesh_arrays(mesh).items():
        np.testing.assert_array_equal(value, navmesh_arrays(again)[name])
    rings = obstacle_rings(mesh, r)
    assert len(rings) == 2
    signed = [0.5 * np.sum(g[:, 0] * np.roll(g[:, 1], -1) - np.roll(g[:, 0], -1) * g[:, 1]) for g in rings]
    assert sorted(np.sign(signed)) == [-1.0, 1.0]  # the room boundary clockwise, the pillar counter-clockwise
    walls = shapely.union_all([LineString(np.vstack([g, g[:1]])) for g in rings])
    d = shapely.distance(walls, shapely.points(mesh.vertices))
    assert d.min() >= r - 1e-6


def test_hole_touching_the_outer_contour_keeps_the_mesh(tmp_path) -> None:
    """Generated office_0490 (seed 0): a hole's contour touches the outer one, so ``make_valid`` returns a
    GeometryCollection(MultiPolygon, LineString); the mesh must keep the polygons (it came out empty)."""
    from song.datasets.scenes import load_scene_package
    from song.datasets.scenes.generate import generate_scene
    from song.pipeline.crowd.navmesh import legal_centres, scene_navmesh

    package = load_scene_package(generate_scene("office_0490", "office", 0, tmp_path))
    mesh = scene_navmesh(package, 0.25, 0.05)
    legal_area = legal_centres(package, 0.25).sum() * package.occupancy.resolution**2
    assert len(mesh.triangles) > 0
    assert 0.9 * legal_area < mesh.area <= 1.02 * legal_area


def test_carvings_are_remembered_and_equal_a_fresh_build() -> None:
    """A repeated carving returns the remembered mesh; its query arrays (spatial hashes kept through the
    build) equal those of the same mesh rebuilt from its plain arrays, and paths keep clear of the discs."""
    from song.geometry import navmesh as nm

    room = orient(Polygon([(0, 0), (6, 0), (6, 4), (0, 4)]), 1.0)
    mesh = navmesh_from_polygons([room], PARAMS)
    discs = np.array([[3.0, 2.0], [3.0, 0.6]])
    carved = nm.carve_discs(mesh, discs, 0.6)
    assert nm.carve_discs(mesh, discs.copy(), 0.6) is carved
    assert nm.carve_discs(mesh, discs, 0.5) is not carved
    rebuilt = navmesh_from_arrays(navmesh_arrays(carved))
    for mine, fresh in zip(carved._kernel_args(), rebuilt._kernel_args(), strict=True):
        np.testing.assert_array_equal(mine, fresh)
    res = carved.find_path(np.array([1.0, 2.0]), np.array([5.0, 2.0]), allow_partial=False)
    assert res.status == "ok"
    along = np.concatenate([np.linspace(a, b, 50) for a, b in zip(res.points[:-1], res.points[1:], strict=True)])
    assert np.hypot(*(along[:, None] - discs[None]).transpose(2, 0, 1)).min() >= 0.6 - 1e-6
    for k in range(nm.CARVINGS_KEPT + 1):  # the least recently used carving goes first
        nm.carve_discs(mesh, np.array([[1.0 + 0.01 * k, 1.0]]), 0.3)
    assert nm.carve_discs(mesh, discs, 0.6) is not carved
