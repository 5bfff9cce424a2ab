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
from song.datasets.scenes.procthor import (
    FLOOR_OBJECT_MAX_BOTTOM_M,
    import_procthor,
    load_asset_table,
    unity_to_world,
    unity_yaw_axes,
)
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


def test_every_floor_object_is_kept_with_the_real_asset_database(imported: list[Path]) -> None:
    """Sized from the procthor package's database: every object standing on the floor is on the map."""
    table = load_asset_table()
    for root in imported:
        house = json.loads((shared_file(HOUSES) / f"{root.name.removeprefix('procthor_')}.json").read_text())
        on_floor = [
            o
            for o in house["objects"]
            if o["position"]["y"] - table[o["assetId"]]["boundingBox"]["y"] / 2 <= FLOOR_OBJECT_MAX_BOTTOM_M
        ]
        assert len(load_scene_package(root).semantic_map.objects) == len(on_floor) >= 17


def test_missing_assets_are_counted_and_named_per_house(tmp_path: Path) -> None:
    table = load_asset_table()
    house = json.loads((shared_file(HOUSES) / "house_6.json").read_text())
    gone = {o["assetId"] for o in house["objects"] if o["position"]["y"] < 1.0}
    gone = sorted(gone)[: len(gone) // 2]
    missing = sum(o["assetId"] in gone for o in house["objects"] if o["position"]["y"] < 1.0)
    db = tmp_path / "assets.json"
    db.write_text(json.dumps({k: v for k, v in table.items() if k not in gone}))
    src = tmp_path / "houses"
    src.mkdir()
    (src / "house_6.json").write_text(json.dumps(house))
    [result] = import_procthor(src, tmp_path / "out", assets=db, splat=False)
    assert result.error == "" and result.unsized == missing > 0
    assert f"{missing} object(s)" in result.warning and "procthor_house_6" in result.warning
    # and the command line says so
    from typer.testing import CliRunner

    from song.cli import app

    out = CliRunner().invoke(
        app,
        ["scenes", "import", "procthor", str(src), "--out", str(tmp_path / "cli"), "--assets", str(db), "--no-splat"],
    )
    assert out.exit_code == 0, out.output
    assert f"{missing} object(s) skipped" in " ".join(out.output.split())


def test_house_without_objects_goes_through_every_stage(tmp_path: Path) -> None:
    """The regression: a house left with no objects crashed the intents stage."""
    from song.config import SongConfig
    from song.datasets.run import read_intents
    from song.pipeline.chain import iter_run

    house = json.loads((shared_file(HOUSES) / "house_6.json").read_text())
    house["objects"] = []
    src = tmp_path / "houses"
    src.mkdir()
    (src / "house_6.json").write_text(json.dumps(house))
    [result] = import_procthor(src, tmp_path / "scenes", splat=True, spacing=0.1)
    assert result.error == "" and (result.path / "3dgs_compressed.ply").is_file()
    stages = ("intents", "crowd", "motion", "binding")
    [scene] = iter_run(tmp_path / "scenes", tmp_path / "run", SongConfig(seed=0), stages, executor="serial")
    assert scene.status == "ok", scene.error
    intents = read_intents(tmp_path / "run" / "scenes" / result.scene_id)
    assert intents.intents == [] and "object" in intents.notes[0]


# ---- houses written by our own code from the schema (tests/datasets/scenes/procthor_factory.py) ----
def _import_own(tmp_path: Path, open_plan: bool = True, splat: bool = False) -> Path:
    from tests.datasets.scenes.procthor_factory import write_house

    house, table = write_house(tmp_path / "houses", open_plan=open_plan)
    results = import_procthor(house, tmp_path / "scenes", assets=table, splat=splat)
    assert [r.error for r in results] == [""]
    return results[0].path


def _free_along(package, a, b, n: int = 40) -> np.ndarray:
    """Whether the occupancy cells along the segment a→b (our x, y) are free."""
    pts = np.linspace(a, b, n)
    rc = package.occupancy.to_cell(pts)
    return package.occupancy.free[rc[:, 0], rc[:, 1]]


def test_empty_walls_are_open_plan_connections(tmp_path: Path) -> None:
    from song.datasets.scenes.dressing import DressingHints, build_dressing

    package = load_scene_package(_import_own(tmp_path))
    assert _free_along(package, (4.0, 0.2), (4.0, 3.8)).all()  # the kitchen–living-room boundary is open
    assert not _free_along(package, (0.2, 4.0), (3.8, 4.0)).any()  # the kitchen–bedroom wall stays
    walls = build_dressing(package.semantic_map, package.occupancy, DressingHints()).walls
    from shapely.geometry import LineString

    boundary = LineString([(4.0, 0.3), (4.0, 3.7)])
    assert not any(w.intersects(boundary) for w in walls)  # no wall geometry (USD or Gaussians) there
    closed = load_scene_package(_import_own(tmp_path / "closed", open_plan=False))
    assert not _free_along(closed, (4.0, 0.6), (4.0, 3.4)).any()


def test_door_holes_are_measured_from_the_first_corner_of_wall0s_polygon(tmp_path: Path) -> None:
    from song.datasets.scenes.procthor import _hints
    from tests.datasets.scenes.procthor_factory import open_plan_house

    package = load_scene_package(_import_own(tmp_path))
    assert _free_along(package, (6.8, 4.0), (7.6, 4.0)).all()  # 0.3–1.3 m from (8, 4) toward (4, 4)
    assert not _free_along(package, (4.4, 4.0), (5.2, 4.0)).any()  # not mirrored onto the dresser
    openings = _hints(open_plan_house(), {}, 0.1).openings
    ends = sorted(sorted(map(tuple, np.round([o.a, o.b], 6))) for o in openings)
    assert ends == [[(2.0, 0.0), (3.0, 0.0)], [(6.7, 4.0), (7.7, 4.0)]]


@pytest.mark.parametrize("open_plan", [True, False])
def test_scenes_check_finds_every_object_the_house_makes_reachable(tmp_path: Path, open_plan: bool) -> None:
    from typer.testing import CliRunner

    from song.cli import app

    root = _import_own(tmp_path, open_plan=open_plan)
    result = CliRunner().invoke(app, ["scenes", "check", str(root)])
    assert result.exit_code == 0, result.output
    if open_plan:
        assert "cannot be reached" not in result.output, result.output
    else:  # walled off, the kitchen's only door is to the outside: its objects are cut off, as the JSON says
        assert "cannot be reached" in result.output and "fridge_1" in result.output


@pytest.mark.parametrize(("scale", "said"), [(1e306, "finite and within"), (200.0, "max_image_pixels")])
def test_an_absurd_house_is_refused_before_any_grid_is_allocated(tmp_path: Path, scale: float, said: str) -> None:
    from tests.datasets.scenes.procthor_factory import ASSETS, open_plan_house

    house = open_plan_house()
    for room in house["rooms"]:
        for p in room["floorPolygon"]:
            p["x"], p["z"] = p["x"] * scale, p["z"] * scale
    (tmp_path / "houses").mkdir()
    (tmp_path / "houses" / "huge.json").write_text(json.dumps(house))
    table = tmp_path / "assets.json"
    table.write_text(
        json.dumps(
            {k: {"objectType": t, "boundingBox": dict(zip("xyz", s, strict=True))} for k, (t, s) in ASSETS.items()}
        )
    )
    (result,) = import_procthor(tmp_path / "houses" / "huge.json", tmp_path / "scenes", assets=table, splat=False)
    assert result.path is None and said in result.error and "rooms" in result.error
    assert not (tmp_path / "scenes").exists() or not any((tmp_path / "scenes").iterdir())


def test_scenes_check_prints_bracketed_ids_and_messages_as_they_are(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from song.cli import app

    root = _import_own(tmp_path)
    data = json.loads((root / "semantic_map.json").read_text())
    data["venue_type"] = "home[/]"
    (root / "semantic_map.json").write_text(json.dumps(data))
    result = CliRunner().invoke(app, ["scenes", "check", str(root)])
    assert "MarkupError" not in repr(result.exception) and "home[/]" in result.output, result.output
