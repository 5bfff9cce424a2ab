"""Scene navmeshes: legal paths, near-optimal lengths against a fine grid, reachability, stored bytes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from song.config import SongConfig
from song.datasets.scenes import load_scene_package
from song.geometry._navmesh_reference import grid_path_length
from song.pipeline.crowd.navmesh import legal_centres, load_navmesh, save_navmesh, scene_navmesh
from tests.conftest import SAMPLES

CFG = SongConfig().crowd
R = CFG.agent_radius_m
GRID_SLACK = 1.01  # our length ≤ the 0.05 m 16-connected grid's + 1 % (the grid is itself ≥ the true length)
SAMPLE_STEP_M = 0.005  # path samples for the legality check


def _samples(points: np.ndarray) -> np.ndarray:
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / SAMPLE_STEP_M)) + 1)
        out.append(a + (b - a) * np.linspace(0.0, 1.0, n)[1:, None])
    return np.vstack(out)


def _check_paths(package, mesh, n_pairs: int, seed: int) -> None:
    grid = package.occupancy
    legal = legal_centres(package, R)
    occupied = grid.to_world(np.argwhere(~grid.free))
    rng = np.random.default_rng(seed)
    main = mesh.component == np.bincount(mesh.component).argmax()
    tri = mesh.vertices[mesh.triangles[main]]
    for _ in range(n_pairs):
        # two random points of the main part (uniform in a random triangle)
        pts = []
        for t in tri[rng.integers(0, len(tri), 2)]:
            u, v = rng.uniform(size=2)
            u, v = (1 - u, 1 - v) if u + v > 1 else (u, v)
            pts.append(t[0] + u * (t[1] - t[0]) + v * (t[2] - t[0]))
        res = mesh.find_path(pts[0], pts[1])
        assert res.status == "ok", res.reason
        assert np.array_equal(res.points[0], pts[0]) and np.array_equal(res.points[-1], pts[1])
        s = _samples(res.points)
        # never crosses a cell within the agent radius of an occupied cell
        rc = grid.to_cell(s)
        assert legal[rc[:, 0], rc[:, 1]].all()
        tree = shapely.STRtree(shapely.points(occupied))
        nearest = occupied[tree.nearest(shapely.points(s))]
        assert np.linalg.norm(s - nearest, axis=1).min() >= R
        straight = float(np.linalg.norm(pts[1] - pts[0]))
        assert res.length >= straight - 1e-9
        assert res.length <= grid_path_length(mesh, pts[0], pts[1], cell=0.05) * GRID_SLACK


def test_tiny_scene_paths_are_legal_and_short(make_scene) -> None:
    package = load_scene_package(make_scene())
    mesh = scene_navmesh(package, R, CFG.contour_error_m)
    assert mesh.component.max() == 0  # the door joins the two rooms
    _check_paths(package, mesh, 12, seed=0)
    # room A to room B goes through the door (x = 4 m, y in [1.5, 2.5] m)
    res = mesh.find_path(np.array([1.5, 3.4]), np.array([5.0, 0.5]))
    assert res.status == "ok" and len(res.points) >= 3
    door = [p for p in res.points[1:-1] if abs(p[0] - 4.0) < 0.2]
    assert door and all(1.5 + R - 0.01 <= p[1] <= 2.5 - R + 0.01 for p in door)


@pytest.mark.parametrize("scene", ["procthor_house_19", "office_0000", "restaurant_0004"])
def test_sample_scene_paths(scene: str) -> None:
    package = load_scene_package(SAMPLES / scene)
    mesh = scene_navmesh(package, R, CFG.contour_error_m)
    _check_paths(package, mesh, 4, seed=1)


@pytest.mark.parametrize("scene", ["procthor_house_1", "procthor_house_19", "procthor_house_6"])
def test_every_procthor_room_is_reachable(scene: str) -> None:
    package = load_scene_package(SAMPLES / scene)
    mesh = scene_navmesh(package, R, CFG.contour_error_m)
    centroid = mesh.vertices[mesh.triangles].mean(axis=1)
    main = np.bincount(mesh.component, weights=np.ones(len(centroid))).argmax()
    for region in package.semantic_map.regions:
        inside = shapely.contains_xy(Polygon(region.polygon), centroid[:, 0], centroid[:, 1])
        assert (inside & (mesh.component == main)).any(), f"{scene}: room {region.id} not on the main mesh part"


def test_navmesh_file_round_trip_and_bytes(make_scene, tmp_path: Path) -> None:
    package = load_scene_package(make_scene())
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    save_navmesh(a, scene_navmesh(package, R, CFG.contour_error_m))
    save_navmesh(b, scene_navmesh(package, R, CFG.contour_error_m))
    assert a.read_bytes() == b.read_bytes()
    (tmp_path / "navmesh.npz").write_bytes(a.read_bytes())
    mesh = load_navmesh(tmp_path)
    assert mesh.params.agent_radius == R and mesh.params.contour_error == CFG.contour_error_m
    assert mesh.params.shape == package.occupancy.free.shape
    res = mesh.find_path(np.array([1.0, 3.0]), np.array([7.0, 1.0]))
    assert res.status == "ok"
