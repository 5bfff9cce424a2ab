"""Procedural avatars: determinism, exact counts, standing geometry, plausible skinning, diversity."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from song.datasets.avatars import load_avatar
from song.datasets.avatars.anthropometry import ANSUR_II, CHILD_SHARE, OLDER_SHARE
from song.datasets.avatars.generate import ACCESSORIES, FABRICS, HAIR, build_pool, generate_avatar, sample_params
from song.datasets.scenes.ply import SH_C0
from song.geometry.skeleton import JOINT_INDEX
from song.util import derive_rng


@pytest.fixture(scope="module")
def crowd_of_avatars():
    return [generate_avatar(derive_rng(7, "avatar", i), f"a{i}", 5_000) for i in range(50)]


def test_pool_is_deterministic_and_index_stable(tmp_path) -> None:
    first = build_pool(tmp_path / "a", 3, seed=5, n_gaussians=5_000)
    again = build_pool(tmp_path / "b", 2, seed=5, n_gaussians=5_000)
    for a, b in zip(first, again, strict=False):
        assert a.read_bytes() == b.read_bytes()  # avatar i depends on (seed, i) only
    other = build_pool(tmp_path / "c", 1, seed=6, n_gaussians=5_000)
    assert other[0].read_bytes() != first[0].read_bytes()
    asset = load_avatar(first[0])  # round trip through the format, hash checked
    assert asset.meta["generator"]["seed"] == 5 and asset.meta["source"] == "procedural"


@pytest.mark.parametrize("n", [5_000, 20_000, 33_333])
def test_exact_count_standing_geometry_and_valid_skinning(n: int) -> None:
    asset = generate_avatar(derive_rng(1, "avatar", n), "x", n)
    cloud = asset.gaussians
    assert len(asset) == n
    assert abs(float(cloud.means[:, 2].min())) < 0.01
    assert abs(float(np.ptp(cloud.means[:, 2])) - asset.height_m) <= 0.02 * asset.height_m
    np.testing.assert_allclose(np.linalg.norm(cloud.quats, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(asset.skin_weights.sum(axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(asset.rest_joints[JOINT_INDEX["head"], 2] / asset.height_m, 0.875, atol=1e-4)
    with pytest.raises(ValueError, match="n_gaussians"):
        generate_avatar(derive_rng(0), "x", 1_000)


def test_gaussians_skin_to_the_body_part_they_sit_on(crowd_of_avatars) -> None:
    for asset in crowd_of_avatars[:10]:
        means, top = asset.gaussians.means, asset.skin_indices[:, 0]
        rest = asset.rest_joints
        head = means[:, 2] > rest[JOINT_INDEX["head"], 2] + 0.05 * asset.height_m
        assert np.isin(top[head], [JOINT_INDEX["head"], JOINT_INDEX["neck"]]).mean() > 0.98
        knee, ankle = rest[JOINT_INDEX["left_knee"]], rest[JOINT_INDEX["left_ankle"]]
        mid_shin = 0.5 * (knee + ankle)
        near = np.linalg.norm(means - mid_shin, axis=1) < 0.06 * asset.height_m
        if asset.meta["generator"]["bottom"] != "skirt":  # a skirt's hem may hang at shin height
            assert (top[near] == JOINT_INDEX["left_knee"]).mean() > 0.95
        hand = np.linalg.norm(means - rest[JOINT_INDEX["right_hand"]], axis=1) < 0.03 * asset.height_m
        assert np.isin(top[hand], [JOINT_INDEX["right_wrist"], JOINT_INDEX["right_hand"]]).all()


def _histogram(asset) -> np.ndarray:
    rgb = np.clip(0.5 + SH_C0 * asset.gaussians.sh_dc.astype(np.float64), 0, 1 - 1e-9)
    bins = (rgb * 8).astype(int)
    hist = np.bincount(bins[:, 0] * 64 + bins[:, 1] * 8 + bins[:, 2], minlength=512).astype(float)
    return hist / hist.sum()


def test_identities_are_visibly_distinct(crowd_of_avatars) -> None:
    """Pairwise L1 distance of 8³-bin colour histograms: 0 = same colours, 2 = disjoint colours.

    Two avatars wearing the same colours in different places would still be told apart by their
    parameters; the colour check asks for more: no pair shares (almost) the same palette. 0.5 means
    at least 25 % of the Gaussians fall in colour bins the other avatar does not use.
    """
    hists = [_histogram(a) for a in crowd_of_avatars]
    distances = [np.abs(a - b).sum() for a, b in itertools.combinations(hists, 2)]
    assert min(distances) > 0.5, min(distances)  # measured: min 0.99, median 1.91 (seed 7)
    params = {str(sorted(a.meta["generator"].items())) for a in crowd_of_avatars}
    assert len(params) == len(crowd_of_avatars)
    kinds = {
        (a.meta["generator"]["top"], a.meta["generator"]["bottom"], a.meta["generator"]["hair"])
        for a in crowd_of_avatars
    }
    assert len(kinds) >= 15  # clothing and hair vary, not only colours


def test_parameters_cover_the_documented_ranges() -> None:
    params = [sample_params(derive_rng(3, i)) for i in range(400)]
    adults = [p.height_m for p in params if p.age_group != "child"]
    assert 1.4 <= min(adults) and max(adults) <= 1.97  # ±3 SD, older adults 3 cm shorter
    assert set(HAIR) == {p.hair for p in params}
    assert {p.pattern for p in params} == {"solid", "stripes", "two_tone"}
    assert any(p.dress for p in params) and {p.bottom for p in params} == {"trousers", "shorts", "skirt"}
    assert {a for p in params for a in p.accessories} == set(ACCESSORIES)
    assert {p.top_fabric for p in params} == set(FABRICS)


def test_anthropometry_of_a_500_identity_pool_matches_ansur_ii() -> None:
    """Adults of each sex: means within 2 % and spreads within 10 % of the cited ANSUR II figures."""
    params = [sample_params(derive_rng(11, "avatar", i)) for i in range(500)]
    for sex in ("male", "female"):
        adults = [p for p in params if p.sex == sex and p.age_group == "adult"]
        assert len(adults) > 150
        for name, values in (
            ("stature", [p.height_m for p in adults]),
            ("biacromial", [p.biacromial_m for p in adults]),
            ("hip", [p.hip_m for p in adults]),
            ("chest_depth", [p.chest_depth_m for p in adults]),
        ):
            mean, sd = ANSUR_II[sex][name]
            assert abs(np.mean(values) / mean - 1) <= 0.02, (sex, name, np.mean(values), mean)
            assert abs(np.std(values) / sd - 1) <= 0.10, (sex, name, np.std(values), sd)
    groups = [p.age_group for p in params]
    assert abs(groups.count("child") / 500 - CHILD_SHARE) < 0.03
    assert abs(groups.count("older") / 500 - OLDER_SHARE) < 0.04
    kids = [p.height_m for p in params if p.age_group == "child"]
    assert 1.0 < min(kids) and max(kids) < 1.7


def test_skin_tones_of_a_500_identity_pool_cover_the_monk_scale_evenly() -> None:
    """Skin colours are the Monk Skin Tone swatches (mixed in linear light), places drawn evenly over MST 1–10."""
    from song.datasets.avatars.generate import MST_HEX, SKIN_TONES, skin_colour

    assert SKIN_TONES.shape == (10, 3) and MST_HEX[0] == "f6ede4" and MST_HEX[-1] == "292420"
    np.testing.assert_allclose(skin_colour(1.0), SKIN_TONES[0], atol=1e-9)  # a whole place is its swatch
    np.testing.assert_allclose(skin_colour(7.0), SKIN_TONES[6], atol=1e-9)
    np.testing.assert_allclose(skin_colour(10.0), SKIN_TONES[9], atol=1e-9)
    params = [sample_params(derive_rng(11, "avatar", i)) for i in range(500)]
    places = np.array([p.skin_mst for p in params])
    assert places.min() >= 1.0 and places.max() <= 10.0
    counts = np.histogram(places, bins=9, range=(1.0, 10.0))[0]  # one bin between each pair of swatches
    assert counts.min() >= 35 and counts.max() <= 80, counts  # ~55.6 each: even over the scale
    luma = np.array([p.skin for p in params]) @ np.array([0.2126, 0.7152, 0.0722])
    assert (luma < 0.3).mean() > 0.2 and (luma > 0.8).mean() > 0.2  # deep and light skin both well represented
    for p in params[:50]:
        np.testing.assert_allclose(p.skin, skin_colour(p.skin_mst), atol=2e-3)  # colour and recorded place agree


@pytest.fixture(scope="module")
def full_avatars():
    return [generate_avatar(derive_rng(5, "avatar", i), f"f{i}", 40_000) for i in range(6)]


def test_hands_face_and_hair_skin_to_their_joints(full_avatars) -> None:
    """Fingers and palms follow the wrists and hands; the face and hair follow the head."""
    for asset in full_avatars:
        means, top, rest, h = asset.gaussians.means, asset.skin_indices[:, 0], asset.rest_joints, asset.height_m
        for side in ("left", "right"):
            sign = 1.0 if side == "left" else -1.0
            beyond = sign * means[:, 1] > sign * rest[JOINT_INDEX[f"{side}_wrist"], 1] + 0.01 * h
            assert beyond.sum() > 400  # palm, thumb and fingers: about 2 % of the Gaussians
            assert np.isin(top[beyond], [JOINT_INDEX[f"{side}_wrist"], JOINT_INDEX[f"{side}_hand"]]).all()
        head = rest[JOINT_INDEX["head"]]
        face = (means[:, 0] > head[0] + 0.06 * h / 1.75) & (means[:, 2] > head[2] + 0.06 * h / 1.75)
        assert face.sum() > 200
        assert np.isin(top[face], [JOINT_INDEX["head"], JOINT_INDEX["neck"]]).mean() > 0.99
        assert asset.meta["body_radius_m"] > 0.15


def test_no_flying_splats_in_gait_poses(full_avatars) -> None:
    """Posed through a gait cycle, every Gaussian stays within 3 cm of the posed body volume: capsules
    around each joint's bones, as thick as the Gaussians that joint drives in the rest pose."""
    from song.config import MotionConfig
    from song.datasets.avatars.skinning import bone_segments, joint_distances
    from song.geometry.fk import skinning_transforms
    from song.geometry.lbs import SkinnedGaussians, lbs_positions
    from song.pipeline.motion import ProceduralGait
    from song.pipeline.motion.synthetic import steady_walk

    motion = ProceduralGait(MotionConfig()).generate([steady_walk(1.4, seconds=4.0)], [""], [3])[0]
    frames = np.arange(60, 120, 4)  # one stride at full speed
    for asset in full_avatars[:3]:
        rest, h = asset.rest_joints.astype(np.float64), asset.height_m
        scale = h / motion.height_m
        transforms = skinning_transforms(rest, motion.local_quats[frames], motion.root_pos[frames] * scale)
        means = asset.gaussians.means.astype(np.float64)
        top = asset.skin_indices[:, 0].astype(int)
        rest_d = joint_distances(means, rest, h)[np.arange(len(means)), top]
        thickness = np.zeros(24)
        np.maximum.at(thickness, top, rest_d)
        start, end, owner = bone_segments(rest, h)
        skin = SkinnedGaussians.build(
            asset.gaussians.means, asset.gaussians.quats, asset.skin_indices, asset.skin_weights
        )
        for f in range(len(frames)):
            posed = lbs_positions(skin, transforms[f].astype(np.float32)).astype(np.float64)
            a = np.einsum("sij,sj->si", transforms[f][owner, :, :3], start) + transforms[f][owner, :, 3]
            b = np.einsum("sij,sj->si", transforms[f][owner, :, :3], end) + transforms[f][owner, :, 3]
            gap = np.full(len(posed), np.inf)
            for k in range(len(a)):
                ab = b[k] - a[k]
                u = np.clip((posed - a[k]) @ ab / max(ab @ ab, 1e-12), 0, 1)
                d = np.linalg.norm(posed - (a[k] + u[:, None] * ab), axis=1) - thickness[owner[k]]
                gap = np.minimum(gap, d)
            assert gap.max() <= 0.03, (asset.avatar_id, int(frames[f]), float(gap.max()))


def _silhouette(asset, cell: float = 0.02) -> np.ndarray:
    """Front view occupancy (y, z) on a fixed 1.2 × 2.1 m grid, arms included."""
    m = asset.gaussians.means
    grid = np.zeros((int(2.1 / cell), int(1.2 / cell)), bool)
    iz = np.clip((m[:, 2] / cell).astype(int), 0, grid.shape[0] - 1)
    iy = np.clip(((m[:, 1] + 0.6) / cell).astype(int), 0, grid.shape[1] - 1)
    grid[iz, iy] = True
    return grid


def test_silhouettes_vary(crowd_of_avatars) -> None:
    masks = [_silhouette(a) for a in crowd_of_avatars]
    ious = [(a & b).sum() / (a | b).sum() for a, b in itertools.combinations(masks, 2)]
    assert max(ious) < 0.97 and float(np.median(ious)) < 0.85, (max(ious), float(np.median(ious)))
