"""AMASS export: exact file round trip, decode + FK within 1 mm, frame and joint-map conventions."""

from __future__ import annotations

import numpy as np
import pytest

from song.errors import FormatError
from song.geometry.fk import forward_kinematics
from song.geometry.rotations import quat_normalize, quat_to_matrix
from song.geometry.skeleton import rest_joints
from song.pipeline.motion.amass import C_SMPL_TO_BODY, from_amass, pelvis_j0, read_amass, to_amass, write_amass

RNG = np.random.default_rng(5)


def _motion(n: int = 40, height: float = 1.72):
    rest = rest_joints(height)
    quats = quat_normalize(RNG.normal(size=(n, 24, 4)))
    root = RNG.normal(size=(n, 3)) + [0, 0, 0.9]
    return rest, quats, root


def test_file_round_trip_is_exact(tmp_path):
    rest, quats, root = _motion()
    amass = to_amass(quats, root, 30.0)
    write_amass(tmp_path / "a.npz", amass)
    back = read_amass(tmp_path / "a.npz")
    for key, value in amass.items():
        assert np.array_equal(back[key], value), key
    assert back["poses"].shape == (40, 156) and back["betas"].shape == (16,)
    assert str(back["gender"]) == "neutral" and float(back["mocap_framerate"]) == 30.0
    assert float(back["mocap_time_length"]) == pytest.approx(40 / 30)
    # SMPL-X spellings are views of the SMPL-H layout
    assert np.array_equal(back["root_orient"], back["poses"][:, :3])
    assert np.array_equal(back["pose_body"], back["poses"][:, 3:66])
    assert np.array_equal(back["pose_hand"], back["poses"][:, 66:])


def test_decode_and_fk_reproduce_joints():
    rest, quats, root = _motion()
    q32, r32 = quats.astype(np.float32).astype(np.float64), root.astype(np.float32).astype(np.float64)
    joints = forward_kinematics(rest, q32, r32)[0]
    decoded_q, decoded_root = from_amass(to_amass(q32, r32, 30.0))
    assert np.abs(forward_kinematics(rest, decoded_q, decoded_root)[0] - joints).max() < 1e-3
    assert np.abs(forward_kinematics(rest, decoded_q, decoded_root)[0] - joints).max() < 1e-6  # float32 quats
    assert np.abs(quat_to_matrix(decoded_q) - quat_to_matrix(quat_normalize(q32))).max() < 1e-9


def test_smplx_only_file_is_read(tmp_path):
    rest, quats, root = _motion(5)
    amass = to_amass(quats, root, 30.0)
    np.savez(tmp_path / "x.npz", trans=amass["trans"], root_orient=amass["root_orient"], pose_body=amass["pose_body"])
    back = read_amass(tmp_path / "x.npz")
    assert np.array_equal(back["poses"][:, :66], amass["poses"][:, :66])
    assert not back["poses"][:, 66:].any()
    np.savez(tmp_path / "bad.npz", trans=amass["trans"])
    with pytest.raises(FormatError, match="poses"):
        read_amass(tmp_path / "bad.npz")


def test_frame_conventions():
    rest = rest_joints(1.8)
    identity = np.zeros((1, 24, 4))
    identity[..., 0] = 1.0
    root = np.array([[1.0, 2.0, rest[0, 2]]])
    amass = to_amass(identity, root, 30.0)
    # an unrotated body (facing world +x) has root_orient = C: SMPL's +Z (forward) maps to world +x
    root_orient = quat_to_matrix(from_amass(amass)[0][0, 0]) @ C_SMPL_TO_BODY
    assert np.allclose(root_orient @ [0, 0, 1], [1, 0, 0])
    assert np.allclose(root_orient @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(root_orient @ [1, 0, 0], [0, 1, 0])
    assert not amass["poses"][:, 3:].any()
    # AMASS: an SMPL body's pelvis lands at J0 + trans, J0 the model's rest pelvis at zero betas (SMPL
    # neutral: 22 cm below the model origin, 2.8 cm forward) -- not our pelvis height above the floor
    assert np.allclose(pelvis_j0(), [-0.001795, -0.223333, 0.028219])
    np.testing.assert_allclose(amass["trans"] + pelvis_j0(), root, atol=1e-12)
    # J0 is added unrotated (the root turns about it): world z gets J0's model z, world y its model y
    np.testing.assert_allclose(amass["trans"][0], [1.0 + 0.001795, 2.0 + 0.223333, rest[0, 2] - 0.028219])


def test_hand_joints_map_to_middle_knuckles():
    rest, quats, root = _motion(3)
    poses = to_amass(quats, root, 30.0)["poses"].reshape(3, 52, 3)
    used = np.flatnonzero(np.abs(poses).sum(axis=(0, 2)) > 0)
    assert set(used.tolist()) <= set(range(22)) | {25, 40}
    assert {25, 40} <= set(used.tolist())
