"""Offline intents: deterministic, venue-aware, endpoints free and mutually reachable."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from song.config import SongConfig
from song.datasets.scenes import load_scene_package
from song.geometry.freespace import walkable_cells
from song.geometry.gridpath import distances_from_many
from song.pipeline.intents import generate_intents
from song.pipeline.intents.navigation import walkable
from song.pipeline.intents.offline import venue_vocabulary
from tests.conftest import SAMPLES


def test_same_seed_same_intents_and_endpoints_reachable() -> None:
    package = load_scene_package(SAMPLES / "procthor_house_19")
    config = SongConfig()
    a = generate_intents(package, config, np.random.default_rng(3))
    b = generate_intents(package, config, np.random.default_rng(3))
    assert a.model_dump_json() == b.model_dump_json()
    assert 2 <= len(a.intents) <= config.intents.max_pedestrians
    walk = walkable(package, config.crowd.agent_radius_m, config.crowd.contour_error_m)
    objects = package.semantic_map.object_by_id()
    for intent in a.intents:
        ends = np.array([intent.start_xy, intent.goal_xy])
        assert walk.on_main(ends).all()  # free at the body radius and in one connected component
        assert intent.start_object in objects and intent.goal_object in objects
        assert config.intents.min_path_m <= intent.geodesic_m <= config.intents.max_path_m
        assert 0.5 <= intent.speed <= 1.0 and intent.provenance.provider == "offline"
    starts = np.array([i.start_xy for i in a.intents])
    gaps = np.linalg.norm(starts[:, None] - starts[None], axis=-1) + np.eye(len(starts)) * 9
    assert gaps.min() >= config.intents.min_spawn_separation_m
    assert all(r.reason for r in a.rejected)


def test_walkable_rows_are_fresh_dijkstra_rows() -> None:
    """Kept distance rows equal a fresh search, in any order and with repeats; ``legal`` is walkable_cells."""
    package = load_scene_package(SAMPLES / "procthor_house_19")
    config = SongConfig()
    walk = walkable(package, config.crowd.agent_radius_m, config.crowd.contour_error_m)
    grid = package.occupancy
    np.testing.assert_array_equal(
        walk.legal,
        walkable_cells(grid.free, grid.resolution, config.crowd.agent_radius_m, config.crowd.contour_error_m),
    )
    cells = walk.coarse.cells[:: max(1, len(walk.coarse.cells) // 5)][:5]
    res = grid.resolution * walk.coarse_factor
    points = grid.to_world(cells * walk.coarse_factor)  # a fine cell inside each coarse start cell
    first, _ = walk.geodesics_from(points[[0, 1, 1]])
    again, _ = walk.geodesics_from(points[[2, 1, 0, 3, 4]])
    fresh = distances_from_many(walk.coarse, np.array([walk._coarse_cell(p) for p in points])) * res
    np.testing.assert_array_equal(first, fresh[[0, 1, 1]])
    np.testing.assert_array_equal(again, fresh[[2, 1, 0, 3, 4]])


def test_venues_have_different_vocabularies(make_scene) -> None:
    office = venue_vocabulary("office")
    clinic = venue_vocabulary("clinic")
    home = venue_vocabulary("home")
    assert set(office) != set(clinic) != set(home)
    package = load_scene_package(make_scene())
    intents = generate_intents(package, SongConfig(), np.random.default_rng(0))
    phrases = " ".join(i.activity for i in intents.intents)
    assert intents.intents and any(word in phrases for word in ("printer", "desk", "sofa", "document", "parcel"))


def test_stage_output_is_recorded(sample_run: Path) -> None:
    data = json.loads((sample_run / "scenes/procthor_house_6/intents.json").read_text())
    assert data["provenance"]["provider"] == "offline" and data["intents"]


def test_intents_command_reruns_one_scene(sample_run: Path, tmp_path: Path) -> None:
    import shutil

    from typer.testing import CliRunner

    from song.cli import app

    run = tmp_path / "run"
    shutil.copytree(sample_run, run)
    before = (run / "scenes/procthor_house_1/intents.json").read_bytes()
    result = CliRunner().invoke(
        app,
        [
            "rerun",
            "intents",
            "--run",
            str(run),
            "--scene",
            "procthor_house_1",
            "--set",
            "intents.llm=offline",
            "-j",
            "1",
        ],
    )
    assert result.exit_code == 0, result.output
    assert (run / "scenes/procthor_house_1/intents.json").read_bytes() == before  # same seed, same intents


def test_lobby_with_few_objects_reaches_the_configured_density(tmp_path: Path) -> None:
    """Several people start and end at one object (distinct spots): the lobby gave 6 of 12 before."""
    from song.datasets.scenes.generate import generate_scene
    from song.pipeline.intents.stage import pedestrian_count

    package = load_scene_package(generate_scene("lobby_0002", "lobby", 7, tmp_path, splat=False))
    config = SongConfig()
    intents = generate_intents(package, config, np.random.default_rng(0)).intents
    walk = walkable(package, config.crowd.agent_radius_m, config.crowd.contour_error_m)
    assert len(intents) == pedestrian_count(walk.area_m2, config) >= 10  # the density, with people sharing objects
    standing = np.array([i.start_xy for i in intents] + [i.goal_xy for i in intents])
    gaps = np.linalg.norm(standing[:, None] - standing[None], axis=-1) + np.eye(len(standing)) * 9
    assert gaps.min() >= config.intents.min_spawn_separation_m - 1e-9  # nobody waits on another's spot (to rounding)
