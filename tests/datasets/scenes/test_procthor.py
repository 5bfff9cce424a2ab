"""ProcTHOR import: frame conversion, footprints, free area, every room reachable from every other."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest
from shapely import contains_xy
from shapely.geometry import Polygon

from song.datasets.scenes import load_scene_package
from song.datasets.scenes.procthor import import_procthor, unity_to_world, unity_yaw_axes
from song.geometry.freespace import components, erode
from tests.conftest import SHARED_HOUSES as HOUSES
from tests.conftest import shared_file


def test_frame_conversion_round_trip_and_handedness() -> None:
    pts = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_allclose(unity_to_world(unity_to_world(pts)), pts)
    assert np.linalg.det(np.eye(3)[[0, 2, 1]]) == -1  # a reflection: left-handed → right-handed
    right, forward = unity_yaw_axes(90.0)  # Unity yaw 90° turns +z (our +y) toward +x
    np.testing.assert_allclose(forward, [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(right, [0.0, -1.0], atol=1e-12)


@pytest.fixture(scope="module")
def imported(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("procthor")
    results = import_procthor(shared_file(HOUSES), out, splat=False)
    assert [r.error for r in results] == ["", "", ""]
    return [r.path for r in results]


def test_rooms_connect_and_area_is_plausible(imported: list[Path]) -> None:
    for root in imported:
        package = load_scene_package(root)
        grid = package.occupancy
        legal = erode(grid.free, grid.resolution, 0.25)
        labels, _ = components(legal)
        centres = grid.to_world(np.argwhere(np.ones(grid.shape, bool)))
        flat = labels.ravel()
        found = set()
        regions = package.semantic_map.regions
        assert len(regions) == 4
        for region in regions:
            inside = contains_xy(Polygon(region.polygon), centres[:, 0], centres[:, 1]) & (flat > 0)
            ids, counts = np.unique(flat[inside], return_counts=True)
            found.add(int(ids[np.argmax(counts)]))  # the room's main walkable part
        assert len(found) == 1, f"{root.name}: rooms fall in {len(found)} separate parts"
        free_m2 = grid.free.sum() * grid.resolution**2
        rooms_m2 = sum(Polygon(r.polygon).area for r in regions)
        assert 0.5 * rooms_m2 < free_m2 < rooms_m2


def test_objects_lie_in_their_rooms_and_skip_wall_items(imported: list[Path]) -> None:
    house = json.loads((shared_file(HOUSES) / "house_1.json").read_text())
    package = load_scene_package(imported[0])
    regions = {r.id: Polygon(r.polygon) for r in package.semantic_map.regions}
    for obj in package.semantic_map.objects:
        centre = np.mean(obj.footprint, axis=0)
        assert obj.region is not None and regions[obj.region].buffer(0.05).contains(Polygon(obj.footprint).centroid)
        assert obj.z_max > 0 and np.isfinite(centre).all()
    labels = {o.label for o in package.semantic_map.objects}
    assert not any("painting" in label or "photo" in label for label in labels)
    assert len(package.semantic_map.objects) < len(house["objects"])


def test_jsonl_gz_batch_with_a_bad_house(tmp_path: Path) -> None:
    good = (shared_file(HOUSES) / "house_6.json").read_text()
    lines = [json.dumps(json.loads(good)), '{"rooms": "not a list"}']
    src = tmp_path / "houses.jsonl.gz"
    src.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
    results = import_procthor(src, tmp_path / "out")
    assert results[0].path is not None and results[1].path is None
    assert "houses.jsonl.gz" in results[1].error and "\n" not in results[1].error
