"""The crowd keeps each pedestrian's own body: the radius of the avatar binding gives it, at the height motion gives it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from song.config import BindingConfig, SongConfig
from song.datasets.avatars import load_avatar, save_avatar
from song.datasets.run import read_crowd_status
from song.errors import FormatError
from song.pipeline.bodies import avatar_body, body_height, body_radii
from song.pipeline.chain import iter_run
from song.pipeline.motion import load_motion
from tests.avatar_factory import capsule_avatar
from tests.conftest import SAMPLES

SCENE = "procthor_house_6"


def test_the_crowds_radii_are_the_bound_avatars(tmp_path: Path) -> None:
    config = SongConfig(seed=4)
    cap = config.crowd.agent_radius_m
    run = tmp_path / "run"
    stages = ["intents", "crowd", "motion", "binding"]
    results = list(iter_run(SAMPLES, run, config, stages, executor="serial", scene_ids=[SCENE]))
    assert all(r.status == "ok" for r in results), [r.error for r in results]
    folder = run / "scenes" / SCENE
    status = read_crowd_status(folder)
    bound = json.loads((folder / "binding" / "bindings.json").read_text())["pedestrians"]
    assert len(bound) >= 3
    radii = []
    for b in bound:
        asset = load_avatar(b["asset_path"])
        motion = load_motion(folder / "human_amass" / f"traj_{b['ped_id']}")
        assert motion.height_m == pytest.approx(body_height(config, SCENE, b["ped_id"]), abs=1e-9)
        want = min(cap, asset.meta["body_radius_m"] * motion.height_m / asset.height_m)
        assert status[b["ped_id"]].body_radius_m == pytest.approx(want, abs=1e-6)
        radii.append(want)
    assert np.ptp(radii) > 0.005  # people differ
    assert max(radii) <= cap


def test_an_avatar_without_a_measured_radius_keeps_the_configured_one(tmp_path: Path) -> None:
    pool = tmp_path / "pool"
    for k in range(3):
        save_avatar(capsule_avatar(f"cap_{k}", n=500, seed=k), pool)
    config = SongConfig(seed=1, binding=BindingConfig(avatars_dir=str(pool)))
    assert avatar_body(sorted(pool.iterdir())[0]) == (pytest.approx(1.75, abs=0.01), None)
    assert body_radii(config, "x", [0, 1, 5]) == {0: 0.25, 1: 0.25, 5: 0.25}


def test_an_unreadable_avatar_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "bad.avatar.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(FormatError, match="bad.avatar.npz.*meta_json"):
        avatar_body(bad)
