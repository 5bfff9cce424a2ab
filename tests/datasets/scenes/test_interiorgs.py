"""InteriorGS import, tested on an InteriorGS-format fixture built from an imported ProcTHOR house."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from song.cli import app
from song.datasets.scenes import load_scene_package
from song.datasets.scenes.interiorgs import FRAME, import_interiorgs, interiorgs_to_world
from song.datasets.scenes.procthor import import_procthor
from tests.conftest import SHARED_HOUSES as HOUSES
from tests.conftest import shared_file


def _fixture(tmp: Path) -> tuple[Path, Path]:
    """Write an InteriorGS-format folder from a ProcTHOR house package (our reading of the format)."""
    source = import_procthor(shared_file(HOUSES) / "house_1.json", tmp / "pt", splat=False)[0].path
    package = load_scene_package(source)
    smap, grid = package.semantic_map, package.occupancy
    folder = tmp / "interiorgs" / "0001_839920"
    folder.mkdir(parents=True)
    cv2.imwrite(str(folder / "occupancy.png"), grid.cells)
    x0, y0, x1, y1 = grid.bounds
    (folder / "occupancy.json").write_text(json.dumps({"scale": grid.resolution, "lower": [x0, y0], "upper": [x1, y1]}))
    labels = []
    for k, obj in enumerate(smap.objects):
        fp = np.asarray(obj.footprint)
        corners = [{"x": x, "y": y, "z": z} for z in (obj.z_min, obj.z_max) for x, y in fp]
        labels.append({"ins_id": str(k), "label": obj.label, "bounding_box": corners})
    labels.append({"ins_id": "wall-lamp", "label": "lamp", "bounding_box": [[0, 0, 1.5]] * 8})  # degenerate: skipped
    (folder / "labels.json").write_text(json.dumps(labels))
    rooms = [{"room_type": r.type, "profile": [list(p) for p in r.polygon]} for r in smap.regions]
    (folder / "structure.json").write_text(json.dumps({"rooms": rooms}))
    return folder, source


def test_frame_assumptions_in_one_place() -> None:
    assert FRAME == {"units": "m", "up": "z", "image_row0": "y_max"}
    pts = np.random.default_rng(0).normal(size=(5, 3))
    np.testing.assert_array_equal(interiorgs_to_world(pts), pts)


def test_import_matches_the_source_house(tmp_path: Path) -> None:
    folder, source = _fixture(tmp_path)
    results = import_interiorgs(folder.parent, tmp_path / "out")
    assert [r.error for r in results] == [""]
    mine, theirs = load_scene_package(results[0].path), load_scene_package(source)
    np.testing.assert_array_equal(mine.occupancy.cells, theirs.occupancy.cells)
    assert mine.occupancy.origin == pytest.approx(theirs.occupancy.origin)
    assert len(mine.semantic_map.objects) == len(theirs.semantic_map.objects)
    for a, b in zip(mine.semantic_map.objects, theirs.semantic_map.objects, strict=True):
        assert a.label == b.label and a.region is not None
        np.testing.assert_allclose(np.mean(a.footprint, axis=0), np.mean(b.footprint, axis=0), atol=1e-3)
    assert [r.type for r in mine.semantic_map.regions] == [r.type for r in theirs.semantic_map.regions]


def test_bad_folder_fails_alone(tmp_path: Path) -> None:
    folder, _ = _fixture(tmp_path)
    broken = folder.parent / "broken"
    shutil.copytree(folder, broken)
    (broken / "labels.json").write_text('[{"label": "sofa", "bounding_box": [[0, 0]]}]')
    result = CliRunner().invoke(
        app, ["scenes", "import", "interiorgs", str(folder.parent), "--out", str(tmp_path / "o")]
    )
    assert result.exit_code == 1
    assert (
        "expected 8 finite" in " ".join(result.output.split()) and (tmp_path / "o" / "interiorgs_0001_839920").is_dir()
    )
