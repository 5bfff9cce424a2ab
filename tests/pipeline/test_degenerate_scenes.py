"""Scenes with nothing to do go through every stage: at worst zero pedestrians, with the reason recorded."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from song.config import SongConfig
from song.datasets.run import read_crowd, read_intents
from song.datasets.scenes import Region, SceneObject, SemanticMap, write_scene_package
from song.datasets.scenes.model import OccupancySpec
from song.pipeline.chain import iter_run

STAGES = ("intents", "crowd", "motion", "binding")


def _package(root: Path, scene_id: str, width: float, height: float, objects=(), walls=()) -> Path:
    res = 0.05
    rows, cols = round(height / res), round(width / res)
    cells = np.full((rows, cols), 255, np.uint8)
    cells[:2], cells[-2:], cells[:, :2], cells[:, -2:] = 0, 0, 0, 0
    for x0, y0, x1, y1 in walls:
        cells[rows - round(y1 / res) : rows - round(y0 / res), round(x0 / res) : round(x1 / res)] = 0
    for obj in objects:
        (x0, y0), (x1, y1) = obj.footprint[0], obj.footprint[2]
        cells[rows - round(y1 / res) : rows - round(y0 / res), round(x0 / res) : round(x1 / res)] = 0
    smap = SemanticMap(
        scene_id=scene_id,
        venue_type="office",
        bounds=(0.0, 0.0, width, height),
        occupancy=OccupancySpec(resolution=res, origin=(0.0, 0.0)),
        regions=[Region(id="room", type="office", polygon=[(0, 0), (width, 0), (width, height), (0, height)])],
        objects=list(objects),
    )
    return write_scene_package(root / scene_id, smap, cells)


def _desk(oid: str, x: float, y: float) -> SceneObject:
    fp = [(x, y), (x + 1.0, y), (x + 1.0, y + 0.6), (x, y + 0.6)]
    return SceneObject(id=oid, label="desk", category="workstation", footprint=fp, z_max=0.75, region="room")


@pytest.fixture(scope="module")
def degenerate_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    root = tmp_path_factory.mktemp("degenerate")
    scenes = root / "scenes"
    _package(scenes, "no_objects", 8.0, 5.0)
    _package(scenes, "one_object", 8.0, 5.0, [_desk("desk_1", 2.0, 2.0)])
    _package(scenes, "tiny_room", 2.6, 2.4, [_desk("desk_1", 0.2, 0.2), _desk("desk_2", 1.3, 1.6)])
    # free space everywhere 40 cm wide: no body fits (a 0.15 m strip once eroded)
    strips = [(0.0, y + 0.4, 12.0, y + 0.6) for y in np.arange(0.0, 3.0, 0.6)]
    _package(scenes, "narrow_strips", 12.0, 3.2, [_desk("desk_1", 1.0, 0.0), _desk("desk_2", 9.0, 2.6)], strips)
    # two rooms with no door between them, objects in both
    _package(
        scenes, "two_rooms", 10.0, 5.0, [_desk("desk_1", 1.0, 1.0), _desk("desk_2", 7.0, 3.0)], [(4.9, 0.0, 5.1, 5.0)]
    )
    chain = iter_run(scenes, root / "run", SongConfig(seed=3), STAGES, executor="serial")
    results = {r.scene_id: r for r in chain}
    return root / "run", results


@pytest.mark.parametrize("scene", ["no_objects", "one_object", "tiny_room", "narrow_strips", "two_rooms"])
def test_every_stage_runs(degenerate_run, scene: str) -> None:
    run, results = degenerate_run
    result = results[scene]
    assert result.status == "ok", result.error
    assert set(result.stages) == set(STAGES)
    intents = read_intents(run / "scenes" / scene)
    crowd = read_crowd(run / "scenes" / scene)
    if len(intents.intents) == 0:  # nothing walked: the reason is recorded
        assert intents.rejected or intents.notes, scene
        assert len(crowd.ids) == 0


def test_the_reason_for_no_pedestrians_is_recorded(degenerate_run) -> None:
    run, _ = degenerate_run
    for scene in ("no_objects", "narrow_strips"):
        intents = read_intents(run / "scenes" / scene)
        assert not intents.intents and intents.notes, intents


def test_scenes_check_reports_every_usability_problem(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from song.cli import app
    from song.datasets.scenes import load_scene_package
    from song.pipeline.intents.navigation import usability_problems

    scenes = tmp_path / "scenes"
    strips = [(0.0, y + 0.4, 12.0, y + 0.6) for y in np.arange(0.0, 3.0, 0.6)]
    _package(scenes, "narrow_strips", 12.0, 3.2, [], strips)  # no body fits, no objects: two problems
    buried = _desk("desk_1", 3.0, 2.0)
    _package(scenes, "buried", 8.0, 5.0, [buried], [(2.6, 1.6, 4.4, 3.0)])  # the desk inside a wall block
    _package(scenes, "fine", 8.0, 5.0, [_desk("desk_1", 2.0, 2.0), _desk("desk_2", 5.0, 1.0)])
    problems = {p.name: usability_problems(load_scene_package(p), 0.25, 0.05) for p in sorted(scenes.iterdir())}
    assert problems["fine"] == []
    assert len(problems["narrow_strips"]) == 2  # no walkable area, no objects
    assert any("walkable area" in p for p in problems["narrow_strips"])
    assert any("objects: none" in p for p in problems["narrow_strips"])
    assert problems["buried"] == ["no object can be reached on foot (1 objects in walls or cut off)"]
    result = CliRunner().invoke(app, ["scenes", "check", str(scenes)])
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if line.startswith("FAILED")]
    assert len(lines) == 3 and sum("narrow_strips" in line for line in lines) == 2
    assert "1 ok, 2 failed" in result.output
