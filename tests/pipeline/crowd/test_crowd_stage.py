"""Crowd invariants on every sample scene: spacing, legality, speed, arrivals, determinism."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from song.config import SongConfig
from song.datasets.run import read_crowd, read_crowd_status, read_intents
from song.datasets.scenes import load_scene_package
from song.errors import FormatError
from song.pipeline.chain import iter_run
from song.pipeline.crowd import load_navmesh
from song.pipeline.crowd.realism import stop_facing
from song.pipeline.intents.navigation import walkable
from tests.conftest import SAMPLES

SCENES = sorted(path.name for path in SAMPLES.iterdir() if (path / "semantic_map.json").exists())
R = SongConfig().crowd.agent_radius_m


@pytest.mark.parametrize("scene", SCENES)
def test_crowd_invariants(sample_run: Path, scene: str) -> None:
    scene_dir = sample_run / "scenes" / scene
    crowd = read_crowd(scene_dir)
    assert crowd.xy.shape[0] >= 2
    status = read_crowd_status(scene_dir)
    radius = np.array([status[int(i)].body_radius_m for i in crowd.ids])
    assert ((radius > 0.15) & (radius <= R)).all() and radius.std() > 0  # bodies of their own sizes
    d = np.linalg.norm(crowd.xy[:, None] - crowd.xy[None], axis=-1)
    d[np.arange(len(d)), np.arange(len(d))] = np.inf
    assert (d - (radius[:, None] + radius[None])[..., None]).min() >= -0.01  # bodies never overlap
    walk = walkable(load_scene_package(SAMPLES / scene), R, SongConfig().crowd.contour_error_m)
    assert walk.on_main(crowd.xy.reshape(-1, 2)).all()
    assert load_navmesh(scene_dir).contains(crowd.xy.reshape(-1, 2), tol=1e-6).all()  # on the navmesh
    intents = {i.id: i for i in read_intents(scene_dir).intents}
    steps = np.linalg.norm(np.diff(crowd.xy, axis=1), axis=-1) * 30
    max_speed = np.array([intents[int(i)].speed for i in crowd.ids])
    assert (steps <= max_speed[:, None] * 1.01 + 1e-9).all()
    for k, ped in enumerate(crowd.ids):  # standing at the start before departure
        before = crowd.t < intents[int(ped)].depart_time - 1e-9
        assert np.allclose(crowd.xy[k, before], crowd.xy[k, 0])


def test_most_intents_arrive(sample_run: Path) -> None:
    statuses = [
        v for s in SCENES for v in json.loads((sample_run / "scenes" / s / "crowd_status.json").read_text()).values()
    ]
    arrived = sum(v["status"] == "arrived" for v in statuses)
    assert arrived / len(statuses) >= 0.95, statuses
    assert all(v["reason"] for v in statuses if v["status"] != "arrived")


def test_crowd_status_reads_back_and_names_the_bad_file(sample_run: Path, tmp_path: Path) -> None:
    for scene in SCENES:
        folder = sample_run / "scenes" / scene
        status = read_crowd_status(folder)
        kept = {int(k) for k in read_crowd(folder).ids}
        assert kept == {k for k, v in status.items() if v.status != "removed"}  # only who could not start has no track
    old = tmp_path / "crowd_status.json"  # written before skipped stops were recorded
    old.write_text('{"3": {"status": "removed", "reason": "start overlaps pedestrian 1", "arrival_s": null}}')
    assert read_crowd_status(old)[3].skipped_stops == []
    old.write_text('{"3": {"status": "lost", "reason": ""}}')
    with pytest.raises(FormatError, match="crowd_status.json"):
        read_crowd_status(old)


def test_same_seed_identical_parquet(sample_run: Path, tmp_path: Path) -> None:
    again = tmp_path / "again"
    list(
        iter_run(
            SAMPLES, again, SongConfig(seed=1), ["intents", "crowd"], executor="serial", scene_ids=["procthor_house_6"]
        )
    )
    name = "scenes/procthor_house_6/crowd.parquet"
    assert (again / name).read_bytes() == (sample_run / name).read_bytes()


@pytest.mark.parametrize("scene", SCENES)
def test_routine_chains_are_valid(sample_run: Path, scene: str) -> None:
    """Each leg is reachable within the path limits, dwells fit their activity, stops are free, routines fit."""
    cfg = SongConfig().intents
    intents = read_intents(sample_run / "scenes" / scene).intents
    walk = walkable(load_scene_package(SAMPLES / scene), R, SongConfig().crowd.contour_error_m)
    spots = []
    for intent in intents:
        legs = intent.route()
        assert 1 <= len(legs) <= cfg.max_legs
        assert all(cfg.min_path_m <= leg.geodesic_m <= cfg.max_path_m for leg in legs)
        assert all(3.0 <= leg.dwell_s <= 30.0 for leg in legs[:-1]) and legs[-1].dwell_s == 0.0
        assert walk.on_main(np.array([leg.goal_xy for leg in legs])).all()  # every stop reachable
        busy = intent.depart_time + sum(leg.geodesic_m / intent.speed + leg.dwell_s for leg in legs)
        assert len(legs) == 1 or busy <= cfg.scenario_s + 1e-6
        spots += [intent.start_xy] + [leg.goal_xy for leg in legs[1:]]
    d = np.linalg.norm(np.array(spots)[:, None] - np.array(spots)[None], axis=-1) + np.eye(len(spots)) * 9
    assert d.min() >= cfg.min_spawn_separation_m - 1e-6  # nobody's standing spot is another's
    assert sum(len(i.route()) > 1 for i in intents) >= len(intents) // 2  # routines, not single walks


@pytest.mark.parametrize("scene", SCENES)
def test_pedestrians_face_the_object_they_stand_at(sample_run: Path, scene: str) -> None:
    """At a stop (dwelling or done) and before departing, a pedestrian faces the nearest side of its object."""
    scene_dir = sample_run / "scenes" / scene
    objects = load_scene_package(SAMPLES / scene).semantic_map.object_by_id()
    misses = stop_facing(read_crowd(scene_dir), read_intents(scene_dir / "intents.json").intents, objects)
    assert misses and max(misses) < 5.0, misses
