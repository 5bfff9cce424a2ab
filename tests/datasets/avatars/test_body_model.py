"""Anny bodies: fitted to our skeleton, weights on our joints, recorded in the pool; the procedural fallback."""

from __future__ import annotations

import numpy as np
import pytest

from song.datasets.avatars import body_model
from song.datasets.avatars.generate import _anny_z, default_body, generate_avatar, sample_params
from song.geometry.skeleton import JOINT_INDEX as J
from song.geometry.skeleton import rest_joints
from song.util import derive_rng

needs_anny = pytest.mark.skipif(not body_model.available(), reason="anny is not installed (pip install song[avatars])")


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


@needs_anny
@pytest.mark.parametrize(("sex", "age", "stature"), [("male", 30, 1.82), ("female", 40, 1.58), ("female", 8, 1.27)])
def test_the_body_wraps_our_rest_skeleton(sex: str, age: float, stature: float) -> None:
    """Crown at the stature, soles on the floor, and every limb's flesh around our bone, not Anny's."""
    mesh = body_model.anny_body(stature, body_model.phenotype(sex, age, {}))
    used = np.unique(mesh.faces)
    z = mesh.vertices[used, 2]
    assert abs(float(z.max()) - stature) < 1e-3
    assert abs(float(z.min())) < 0.015 * stature
    np.testing.assert_allclose(mesh.weights.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(mesh.joints, rest_joints(stature))
    rest = mesh.joints
    for side in ("left", "right"):
        for joint, child, limit in (
            ("shoulder", "elbow", 0.09),
            ("elbow", "wrist", 0.07),
            ("hip", "knee", 0.14),
            ("knee", "ankle", 0.09),
        ):
            owned = mesh.weights[:, J[f"{side}_{joint}"]] > 0.95
            assert owned.sum() > 100
            gap = _segment_distance(mesh.vertices[owned], rest[J[f"{side}_{joint}"]], rest[J[f"{side}_{child}"]])
            assert np.percentile(gap, 99) < limit * stature / 1.75, (side, joint, float(np.percentile(gap, 99)))
    # eyes in front of the head joint, level, 5–7 cm apart (an adult's pupils are ~6.3 cm apart)
    assert mesh.eyes[0, 1] > 0 > mesh.eyes[1, 1]
    assert 0.045 * stature / 1.75 < mesh.eyes[0, 1] - mesh.eyes[1, 1] < 0.075
    assert abs(mesh.eyes[0, 2] - mesh.eyes[1, 2]) < 1e-6 and (mesh.eyes[:, 0] > rest[J["head"], 0]).all()
    assert mesh.mouth[2] < mesh.eyes[0, 2] - 0.04 * stature / 1.75


@needs_anny
def test_phenotype_follows_the_identity() -> None:
    old, child = body_model.phenotype("male", 80, {}), body_model.phenotype("female", 8, {"weight": 3.0})
    assert old["gender"] == 0.0 and child["gender"] == 1.0
    assert child["age"] < 1 / 3 < 2 / 3 < old["age"] <= 1.0  # MakeHuman: 11 years at 1/3, 25 at 2/3
    assert child["weight"] == 0.95 and 0.0 <= min(old.values()) and max(child.values()) <= 1.0


@needs_anny
def test_pool_identities_record_their_anny_body() -> None:
    assets = [generate_avatar(derive_rng(9, "avatar", i), f"a{i}", 8_000) for i in range(12)]
    radii = []
    for asset in assets:
        gen = asset.meta["generator"]
        assert gen["body"] == "anny" and gen["anny"]["version"] == body_model.ANNY_VERSION
        assert 0.15 < asset.meta["body_radius_m"] < 0.32
        radii.append((gen["age_group"] == "child", asset.meta["body_radius_m"]))
    assert default_body() == "anny"
    kids = [r for child, r in radii if child]
    if kids:  # a child's body is narrower than any adult's in the sample
        assert max(kids) < min(r for child, r in radii if not child)


@needs_anny
def test_the_eyes_have_irises_and_pupils() -> None:
    p = sample_params(derive_rng(4, "avatar", 0))
    asset = generate_avatar(derive_rng(4, "avatar", 0), "e", 40_000, params=p)
    mesh = body_model.anny_body(p.height_m, body_model.phenotype(p.sex, p.age_years, _anny_z(p)))
    means = asset.gaussians.means.astype(np.float64)
    near = np.linalg.norm(means[:, None, :] - mesh.eyes[None], axis=2).min(axis=1) < 0.02
    rgb = 0.5 + 0.28209479177387814 * asset.gaussians.sh_dc[near].astype(np.float64)
    lum = rgb.mean(axis=1)
    assert near.sum() > 30
    assert (lum < 0.12).any() and (lum > 0.55).any()  # pupils and sclera both present


def test_procedural_body_is_the_fallback(monkeypatch) -> None:
    monkeypatch.setattr(body_model, "available", lambda: False)
    assert default_body() == "procedural"
    asset = generate_avatar(derive_rng(1, "avatar", 0), "p", 6_000)
    assert asset.meta["generator"]["body"] == "procedural" and "anny" not in asset.meta["generator"]
    assert len(asset) == 6_000
    with pytest.raises(ValueError, match="body="):
        generate_avatar(derive_rng(1, "avatar", 0), "p", 6_000, body="smpl")
    with pytest.raises(ValueError, match="Anny is not installed"):
        generate_avatar(derive_rng(1, "avatar", 0), "p", 6_000, body="anny")
