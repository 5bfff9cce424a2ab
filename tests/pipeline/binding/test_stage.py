"""The binding stage on real motions: contract, identity sampling, caches that follow the motion."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from song.config import BindingConfig, SongConfig
from song.datasets.avatars import load_avatar, save_avatar
from song.datasets.avatars.cache import (
    PosedAvatar,
    load_compact_cache,
    load_materialized_cache,
    skin_asset,
)
from song.datasets.run.layout import MOTION_META_FILE
from song.datasets.scenes import load_scene_package
from song.errors import FormatError
from song.geometry.lbs import lbs
from song.geometry.skeleton import JOINT_INDEX
from song.pipeline.binding import run_binding
from song.pipeline.bodies import identity_picks
from song.pipeline.chain import StageContext
from song.pipeline.motion import load_motion, run_motion
from tests.avatar_factory import capsule_avatar
from tests.pipeline.motion.test_stage import write_crowd


@pytest.fixture(scope="module")
def pool(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("pool")
    for i, height in enumerate((1.6, 1.75, 1.9, 1.7)):
        save_avatar(capsule_avatar(f"cap{i}", n=2500, height=height, seed=i), folder)
    return folder


def _bound(make_scene, root: Path, pool: Path, materialize: bool = False) -> StageContext:
    scene = load_scene_package(make_scene())
    config = SongConfig(seed=5, binding=BindingConfig(avatars_dir=str(pool), materialize=materialize))
    scene_dir = root / "run" / "scenes" / scene.scene_id
    write_crowd(scene_dir)
    run_motion(StageContext(scene, scene_dir, root / "run", config, "motion"))
    ctx = StageContext(scene, scene_dir, root / "run", config, "binding")
    run_binding(ctx)
    return ctx


def test_contract_identities_and_determinism(make_scene, tmp_path, pool) -> None:
    ctx = _bound(make_scene, tmp_path / "a", pool)
    bindings = json.loads((ctx.scene_dir / "binding" / "bindings.json").read_text())["pedestrians"]
    assert [b["ped_id"] for b in bindings] == [0, 1, 2]
    assert len({b["avatar_id"] for b in bindings}) == 3  # no repeats while the pool allows
    for b in bindings:
        motion = load_motion(ctx.scene_dir / "human_amass" / f"traj_{b['ped_id']}")
        cache = load_compact_cache(ctx.scene_dir / b["cache_file"])
        asset = load_avatar(b["asset_path"])
        assert b["asset_sha256"] == asset.meta["sha256"]
        assert cache.meta["scale"] == pytest.approx(motion.height_m / asset.height_m)
        assert len(cache) == len(motion.t) and cache.frame0 == int(motion.frame[0])
        np.testing.assert_allclose(cache.rest_joints, motion.rest_joints, atol=1e-5)
    again = _bound(make_scene, tmp_path / "b", pool)
    for name in sorted(p.name for p in (ctx.scene_dir / "binding").iterdir()):
        assert (ctx.scene_dir / "binding" / name).read_bytes() == (again.scene_dir / "binding" / name).read_bytes()


def test_the_motion_folder_names_the_pedestrian(make_scene, tmp_path, pool) -> None:
    ctx = _bound(make_scene, tmp_path, pool)
    before = (ctx.scene_dir / "binding" / "bindings.json").read_bytes()
    meta = ctx.scene_dir / "human_amass" / "traj_1" / MOTION_META_FILE
    data = json.loads(meta.read_text())
    del data["ped_id"]  # a motion written without its id binds as the folder's pedestrian
    meta.write_text(json.dumps(data))
    run_binding(ctx)
    assert (ctx.scene_dir / "binding" / "bindings.json").read_bytes() == before
    meta.write_text(json.dumps({**data, "ped_id": 2}))  # one that claims another's id is refused, named
    with pytest.raises(FormatError, match=r"traj_1/meta.json: ped_id: is 2, the folder's is 1"):
        run_binding(ctx)


def test_identity_sampling_cycles_through_permutations() -> None:
    config = SongConfig(seed=3)
    picks = identity_picks(config, "tiny", [12, 3, 7, 1, 0, 9, 4, 5, 30, 2], 4)
    order = [picks[i] for i in sorted(picks)]
    assert sorted(order[:4]) == [0, 1, 2, 3] and sorted(order[4:8]) == [0, 1, 2, 3]
    assert identity_picks(config, "tiny", [0, 1, 2], 4) == {i: order[i] for i in range(3)}  # a prefix, by id


def _dominant(asset, joint: str) -> np.ndarray:
    return (asset.skin_indices[:, 0] == JOINT_INDEX[joint]) & (asset.skin_weights[:, 0] > 0.95)


def test_avatar_stands_on_the_floor_and_feet_follow_the_foot_joints(make_scene, tmp_path, pool) -> None:
    ctx = _bound(make_scene, tmp_path, pool)
    for b in json.loads((ctx.scene_dir / "binding" / "bindings.json").read_text())["pedestrians"]:
        motion = load_motion(ctx.scene_dir / "human_amass" / f"traj_{b['ped_id']}")
        cache = load_compact_cache(ctx.scene_dir / b["cache_file"])
        asset = load_avatar(b["asset_path"]).scaled(cache.meta["scale"])
        avatar = PosedAvatar.load(load_avatar(b["asset_path"]), cache)
        frames = np.arange(0, len(motion.t), 7)
        for joint in ("left_ankle", "right_ankle"):
            mask = _dominant(asset, joint)
            rest_offset = np.linalg.norm(asset.gaussians.means[mask] - asset.rest_joints[JOINT_INDEX[joint]], axis=1)
            for f in frames:
                posed = avatar.means_at(float(motion.t[f]))[mask]
                offset = np.linalg.norm(posed - motion.joints[f, JOINT_INDEX[joint]], axis=1)
                assert np.abs(offset - rest_offset).max() <= 0.03
        standing = avatar.means_at(float(motion.t[0]))
        assert abs(float(standing[:, 2].min())) <= 0.03


def test_compact_and_materialized_pose_alike(make_scene, tmp_path, pool) -> None:
    ctx = _bound(make_scene, tmp_path, pool, materialize=True)
    for b in json.loads((ctx.scene_dir / "binding" / "bindings.json").read_text())["pedestrians"]:
        cache = load_compact_cache(ctx.scene_dir / b["cache_file"])
        materialized = load_materialized_cache(ctx.scene_dir / b["materialized_file"])
        skin = skin_asset(load_avatar(b["asset_path"]).scaled(cache.meta["scale"]))
        for f in range(0, len(cache), 11):
            t = (cache.frame0 + f) / cache.fps
            means, quats = lbs(skin, cache.transforms_at(t))
            m_means, m_quats = materialized.pose(t)
            near = np.linalg.norm(means - cache.root_pos[f], axis=1) <= 3.0
            assert np.abs(means - m_means)[near].max() <= 0.002
            dots = np.abs((quats * m_quats).sum(-1)).clip(0, 1)
            assert np.degrees(2 * np.arccos(dots)).max() <= 0.5


def test_release_rows_reference_the_binding(make_scene, tmp_path, pool) -> None:
    from song.datasets.bench.export import _avatar_rows
    from song.datasets.bench.io import BlobStore
    from song.datasets.run import RunFolder
    from song.util import sha256_file

    ctx = _bound(make_scene, tmp_path, pool)
    for amass in (False, True):
        store = BlobStore(tmp_path / f"release-{amass}")
        rows = _avatar_rows(RunFolder(ctx.run_dir), ctx.scene_id, [0, 1, 2], store, amass)
        for row in rows:
            cache = load_compact_cache(store.root / row["cache"]["path"])
            assert cache.meta["ped_id"] == row["ped_id"] and cache.meta["avatar_id"] == row["avatar_id"]
            asset = load_avatar(store.root / row["asset"]["path"])
            assert asset.meta["sha256"] == cache.meta["avatar_sha256"]
            assert row["cache"]["sha256"] == sha256_file(store.root / row["cache"]["path"])
            assert (row["amass"] is not None) == amass


def test_materialized_cache_on_the_torch_path_matches_numpy(make_scene, tmp_path, pool, monkeypatch) -> None:
    """The bulk posing moves to torch when a GPU is there; run that path on the CPU and compare."""
    pytest.importorskip("torch")
    from song.datasets.avatars import cache as cache_module

    ctx = _bound(make_scene, tmp_path, pool)
    b = json.loads((ctx.scene_dir / "binding" / "bindings.json").read_text())["pedestrians"][1]
    motion = load_compact_cache(ctx.scene_dir / b["cache_file"])
    asset = load_avatar(b["asset_path"]).scaled(motion.meta["scale"])
    cache_module.write_materialized_cache(tmp_path / "numpy.npz", asset, motion)
    monkeypatch.setattr(cache_module, "accelerator", lambda: "cpu")
    cache_module.write_materialized_cache(tmp_path / "torch.npz", asset, motion)
    a, c = load_materialized_cache(tmp_path / "numpy.npz"), load_materialized_cache(tmp_path / "torch.npz")
    assert np.abs(a.positions.astype(np.float32) - c.positions.astype(np.float32)).max() <= 2e-3
    dots = np.abs((a.rotations.astype(np.float32) * c.rotations.astype(np.float32)).sum(-1))
    assert dots.min() > 0.999


def test_a_pool_avatar_is_checked_once_per_process_and_again_once_rewritten(tmp_path, monkeypatch) -> None:
    from song.pipeline.binding import stage

    monkeypatch.setattr(stage, "_VERIFIED", {})
    reads = []
    real = stage.load_avatar
    monkeypatch.setattr(stage, "load_avatar", lambda path: reads.append(path) or real(path))
    path = save_avatar(capsule_avatar("a1", n=300), tmp_path)
    first = stage._verified_identity(path)
    assert stage._verified_identity(path) is first and len(reads) == 1
    # a rewritten asset is read again, and a corrupted one is refused rather than served from memory
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["rest_joints"] = arrays["rest_joints"] * np.float32(1.01)
    np.savez(path, **arrays)
    os.utime(path, ns=(1, 1))
    with pytest.raises(FormatError, match=r"a1\.avatar\.npz.*sha256"):
        stage._verified_identity(path)
    assert len(reads) == 2
