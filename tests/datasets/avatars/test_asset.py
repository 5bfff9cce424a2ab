"""Avatar asset format: round trips, content hash, one-line errors, weight transfer."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from song.datasets.avatars import export_avatar_ply, import_avatar_ply, load_avatar, save_avatar
from song.datasets.avatars.skinning import transfer_weights
from song.errors import FormatError
from song.geometry.skeleton import JOINT_INDEX, rest_joints
from tests.avatar_factory import capsule_avatar


def _same(a, b) -> None:
    for key in ("means", "quats", "log_scales", "opacity_logits", "sh_dc"):
        np.testing.assert_array_equal(getattr(a.gaussians, key), getattr(b.gaussians, key))
    np.testing.assert_array_equal(a.skin_indices, b.skin_indices)
    np.testing.assert_array_equal(a.skin_weights, b.skin_weights)
    np.testing.assert_array_equal(a.rest_joints, b.rest_joints)
    assert a.meta == b.meta


def test_npz_and_ply_round_trips(tmp_path) -> None:
    asset = capsule_avatar("a1", n=800)
    path = save_avatar(asset, tmp_path)
    assert path.name == "a1.avatar.npz"
    loaded = load_avatar(path)
    _same(asset, loaded)
    save_avatar(loaded, tmp_path / "again")
    assert (tmp_path / "again" / path.name).read_bytes() == path.read_bytes()
    ply, sidecar = export_avatar_ply(loaded, tmp_path / "ply")
    assert ply.suffix == ".ply" and sidecar.name == "a1.skin.npz"
    _same(loaded, import_avatar_ply(ply))


def test_altered_file_is_refused(tmp_path) -> None:
    path = save_avatar(capsule_avatar("a2", n=300), tmp_path)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["means"] = arrays["means"] + np.float32(0.01)
    np.savez(path, **arrays)
    with pytest.raises(FormatError, match=r"a2\.avatar\.npz.*sha256"):
        load_avatar(path)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda a: replace(a, skin_weights=a.skin_weights * 2), "skin_weights"),
        (lambda a: replace(a, skin_indices=np.full_like(a.skin_indices, 30)), "skin_indices"),
        (lambda a: replace(a, rest_joints=a.rest_joints[:10]), "rest_joints"),
        (lambda a: replace(a, meta={**a.meta, "height_m": 9.0}), "height_m"),
    ],
)
def test_invalid_assets_name_the_field(tmp_path, change, field) -> None:
    with pytest.raises(FormatError, match=field):
        save_avatar(change(capsule_avatar("bad", n=200)), tmp_path)
    assert not (tmp_path / "bad.avatar.npz").exists()


def test_weight_transfer_follows_the_nearest_bone() -> None:
    rest = rest_joints(1.8)
    shin = 0.5 * (rest[JOINT_INDEX["left_knee"]] + rest[JOINT_INDEX["left_ankle"]]) + [0.04, 0.0, 0.0]
    thigh = 0.5 * (rest[JOINT_INDEX["right_hip"]] + rest[JOINT_INDEX["right_knee"]]) + [0.0, 0.05, 0.0]
    forearm = 0.5 * (rest[JOINT_INDEX["left_elbow"]] + rest[JOINT_INDEX["left_wrist"]]) + [0.0, 0.0, 0.03]
    knee = rest[JOINT_INDEX["left_knee"]] + [0.05, 0.0, 0.0]
    indices, weights = transfer_weights(np.array([shin, thigh, forearm, knee]), rest, 1.8, smooth_radius=0)
    assert indices[0, 0] == JOINT_INDEX["left_knee"] and weights[0, 0] > 0.99
    assert indices[1, 0] == JOINT_INDEX["right_hip"] and weights[1, 0] > 0.99  # inner thigh stays on its leg
    assert indices[2, 0] == JOINT_INDEX["left_elbow"] and weights[2, 0] > 0.99
    assert set(indices[3, :2]) == {JOINT_INDEX["left_hip"], JOINT_INDEX["left_knee"]}  # blends at the joint
    assert weights[3, 1] > 0.2
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-6)
    assert (np.diff(weights, axis=1) <= 0).all()
