"""Importing a foreign-frame 3DGS PLY avatar: orientation, ground, scale, skinning that follows a motion."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from song.datasets.avatars import save_avatar
from song.datasets.avatars.asset import load_avatar
from song.datasets.avatars.cache import PosedAvatar, load_compact_cache
from song.datasets.avatars.importer import import_ply_avatar
from song.datasets.scenes.ply import write_standard_ply
from song.errors import FormatError
from song.geometry.rotations import matrix_to_quat, quat_mul, quat_normalize
from song.geometry.skeleton import JOINT_INDEX
from song.pipeline.motion import load_motion
from tests.avatar_factory import capsule_avatar
from tests.pipeline.binding.test_stage import _bound

# body frame (x forward, y left, z up) → SMPL/LHM canonical (x left, y up, z forward)
TO_SMPL = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def _foreign_ply(tmp_path, asset, rotation=TO_SMPL, scale=0.8, offset=(0.3, -0.2, 1.5)):
    cloud = asset.gaussians
    turn = matrix_to_quat(rotation)
    foreign = replace(
        cloud,
        means=(scale * cloud.means.astype(np.float64) @ rotation.T + offset).astype(np.float32),
        quats=quat_normalize(quat_mul(np.broadcast_to(turn, cloud.quats.shape), cloud.quats)).astype(np.float32),
        log_scales=cloud.log_scales + np.float32(np.log(scale)),
    )
    path = tmp_path / "lhm_export.ply"
    write_standard_ply(path, foreign)
    return path


@pytest.mark.parametrize("rotation", [TO_SMPL, np.eye(3), np.array([[0.0, -1.0, 0], [1.0, 0, 0], [0, 0, 1.0]])])
def test_import_recovers_the_canonical_avatar(tmp_path, rotation) -> None:
    original = capsule_avatar("orig", n=4000, height=1.7)
    height = float(np.ptp(original.gaussians.means[:, 2]))
    imported = import_ply_avatar(_foreign_ply(tmp_path, original, rotation), "imp", height_m=height)
    assert abs(float(imported.gaussians.means[:, 2].min())) < 1e-6  # stands on z = 0
    np.testing.assert_allclose(imported.gaussians.means, original.gaussians.means, atol=0.01)
    angle = 2 * np.arccos(np.abs((imported.gaussians.quats * original.gaussians.quats).sum(-1)).clip(0, 1))
    assert np.degrees(angle).max() < 0.1


def test_explicit_axes_and_ambiguity(tmp_path) -> None:
    original = capsule_avatar("orig", n=3000)
    path = _foreign_ply(tmp_path, original)
    explicit = import_ply_avatar(path, "imp", height_m=1.75, up="+y", forward="+z")
    auto = import_ply_avatar(path, "imp", height_m=1.75)
    np.testing.assert_allclose(explicit.gaussians.means, auto.gaussians.means)
    with pytest.raises(FormatError, match="forward"):
        import_ply_avatar(path, "imp", up="+y", forward="+y")
    ball = replace(original.gaussians, means=np.random.default_rng(0).normal(size=(3000, 3)).astype(np.float32))
    write_standard_ply(tmp_path / "ball.ply", ball)
    with pytest.raises(FormatError, match=r"ball\.ply"):
        import_ply_avatar(tmp_path / "ball.ply", "ball")


def test_imported_avatar_faces_the_heading_and_feet_follow(make_scene, tmp_path) -> None:
    imported = import_ply_avatar(_foreign_ply(tmp_path, capsule_avatar("orig", n=4000)), "imp", height_m=1.7)
    pool = tmp_path / "pool"
    save_avatar(imported, pool)
    ctx = _bound(make_scene, tmp_path, pool)
    ped = json.loads((ctx.scene_dir / "binding" / "bindings.json").read_text())["pedestrians"][0]  # straight walk
    motion = load_motion(ctx.scene_dir / "human_amass" / f"traj_{ped['ped_id']}")
    cache = load_compact_cache(ctx.scene_dir / ped["cache_file"])
    asset = load_avatar(ped["asset_path"]).scaled(cache.meta["scale"])
    avatar = PosedAvatar.load(load_avatar(ped["asset_path"]), cache)
    foot = (asset.skin_indices[:, 0] == JOINT_INDEX["left_foot"]) & (asset.skin_weights[:, 0] > 0.9)
    ankle = (asset.skin_indices[:, 0] == JOINT_INDEX["left_ankle"]) & (asset.skin_weights[:, 0] > 0.95)
    rest_offset = np.linalg.norm(asset.gaussians.means[ankle] - asset.rest_joints[JOINT_INDEX["left_ankle"]], axis=1)
    walking = np.flatnonzero(np.linalg.norm(np.diff(motion.root_pos[:, :2], axis=0), axis=1) > 0.02)[::10]
    for f in walking:
        posed = avatar.means_at(float(motion.t[f]))
        toes = posed[foot].mean(axis=0) - motion.joints[f, JOINT_INDEX["left_ankle"]]
        velocity = motion.root_pos[f + 1, :2] - motion.root_pos[f, :2]
        cosine = toes[:2] @ velocity / (np.linalg.norm(toes[:2]) * np.linalg.norm(velocity))
        assert cosine > np.cos(np.radians(35))  # the feet point where the pedestrian walks
        offset = np.linalg.norm(posed[ankle] - motion.joints[f, JOINT_INDEX["left_ankle"]], axis=1)
        assert np.abs(offset - rest_offset).max() <= 0.03


GUITAR = (
    Path(__file__).resolve().parents[3].parent
    / "shared"
    / "sample_scenes"
    / "playcanvas_splat"
    / "guitar.compressed.ply"
)


def test_people_pass_the_plausibility_check_and_objects_do_not(tmp_path) -> None:
    from song.datasets.avatars.generate import generate_avatar
    from song.util import derive_rng

    for i in range(4):  # procedural people of all builds, children included by seed
        person = generate_avatar(derive_rng(2, "avatar", i), "p", 8_000)
        height = float(np.ptp(person.gaussians.means[:, 2]))
        import_ply_avatar(_foreign_ply(tmp_path, person), "imp", height_m=height)
    # a thin upright object (a pole with a knob on top) scaled to a person's height
    pole = capsule_avatar("pole", n=3000)
    thin = pole.gaussians.means * np.array([0.2, 0.2, 1.0], np.float32)
    path = _foreign_ply(tmp_path, replace(pole, gaussians=replace(pole.gaussians, means=thin)))
    with pytest.raises(FormatError, match="shape: does not look like a standing person: hip width"):
        import_ply_avatar(path, "pole", up="+y", forward="+z")
    with pytest.raises(FormatError, match="force"):
        import_ply_avatar(path, "pole", force=True)  # forcing needs the axes
    forced = import_ply_avatar(path, "pole", up="+y", forward="+z", force=True)
    assert len(forced) == 3000


@pytest.mark.skipif(not GUITAR.exists(), reason="the guitar sample splat (../shared) is not present")
def test_the_guitar_is_not_a_person() -> None:
    with pytest.raises(FormatError, match="does not look like a standing person"):
        import_ply_avatar(GUITAR, "guitar", height_m=1.75)


def test_degenerate_splats_are_refused_in_one_line_even_when_forced(tmp_path) -> None:
    person = capsule_avatar("p", n=3000)
    g = person.gaussians
    three = replace(g, **{k: getattr(g, k)[:3] for k in ("means", "quats", "log_scales", "opacity_logits", "sh_dc")})
    few = replace(person, gaussians=three)
    with pytest.raises(FormatError, match=r"lhm_export\.ply: vertex: 3 splats; an avatar needs at least 100"):
        import_ply_avatar(_foreign_ply(tmp_path, few), "few", up="+y", forward="+z", force=True)
    means = person.gaussians.means.copy()
    means[:, 2] = 0.9  # every splat at one height: no body height to scale from
    flat = replace(person, gaussians=replace(person.gaussians, means=means))
    with pytest.raises(FormatError, match="vertex: the splats have no extent along the up axis"):
        import_ply_avatar(_foreign_ply(tmp_path, flat), "flat", up="+y", forward="+z", force=True)
