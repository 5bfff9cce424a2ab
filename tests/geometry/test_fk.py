"""Forward kinematics and skinning transforms against the loop twin and geometric invariants."""

from __future__ import annotations

import numpy as np
import pytest

from song.geometry._fk_reference import fk_reference
from song.geometry.fk import forward_kinematics, global_to_local, skinning_transforms
from song.geometry.rotations import quat_identity, quat_normalize, quat_to_matrix
from song.geometry.skeleton import N_JOINTS, PARENTS, rest_joints

RNG = np.random.default_rng(3)


@pytest.mark.parametrize(("frames", "height"), [(1, 1.5), (7, 1.75), (20, 1.95)])
def test_fk_matches_loop_twin(frames, height):
    rest = rest_joints(height)
    quats = quat_normalize(RNG.normal(size=(frames, N_JOINTS, 4)))
    root = RNG.normal(size=(frames, 3))
    joints, rots = forward_kinematics(rest, quats, root)
    ref_joints, ref_rots = fk_reference(rest, quats, root)
    assert np.abs(joints - ref_joints).max() < 1e-12
    assert np.abs(rots - ref_rots).max() < 1e-12


def test_identity_pose_is_the_rest_pose_translated():
    rest = rest_joints(1.8)
    root = np.array([[1.0, 2.0, rest[0, 2]], [-3.0, 0.5, rest[0, 2] - 0.1]])
    joints, rots = forward_kinematics(rest, quat_identity((2, N_JOINTS)), root)
    assert np.allclose(joints, rest[None] - rest[0] + root[:, None])
    assert np.allclose(rots, np.eye(3))


def test_bone_lengths_are_preserved():
    rest = rest_joints(1.6)
    quats = quat_normalize(RNG.normal(size=(30, N_JOINTS, 4)))
    joints, _ = forward_kinematics(rest, quats, RNG.normal(size=(30, 3)))
    bones = np.linalg.norm(joints[:, 1:] - joints[:, PARENTS[1:]], axis=-1)
    rest_bones = np.linalg.norm(rest[1:] - rest[PARENTS[1:]], axis=-1)
    assert np.allclose(bones, rest_bones, atol=1e-12)


def test_skinning_transforms_map_rest_joints_and_points_rigidly():
    rest = rest_joints(1.7)
    quats = quat_normalize(RNG.normal(size=(5, N_JOINTS, 4)))
    root = RNG.normal(size=(5, 3))
    a = skinning_transforms(rest, quats, root)
    joints, rots = forward_kinematics(rest, quats, root)
    mapped = (a[..., :3] @ rest[:, :, None])[..., 0] + a[..., 3]
    assert a.shape == (5, N_JOINTS, 3, 4)
    assert np.abs(mapped - joints).max() < 1e-12
    # a point rigidly attached to a joint keeps its offset in the joint's frame
    point = rest[18] + np.array([0.01, 0.02, -0.03])
    moved = a[:, 18, :, :3] @ point + a[:, 18, :, 3]
    assert np.allclose(moved - joints[:, 18], (rots[:, 18] @ (point - rest[18])))


def test_global_to_local_inverts_fk():
    rest = rest_joints(1.7)
    quats = quat_normalize(RNG.normal(size=(4, N_JOINTS, 4)))
    _, rots = forward_kinematics(rest, quats, np.zeros((4, 3)))
    assert np.abs(global_to_local(rots) - quat_to_matrix(quats)).max() < 1e-12


def test_torch_fk_matches_numpy():
    torch = pytest.importorskip("torch")
    rest = rest_joints(1.7)
    quats = quat_normalize(RNG.normal(size=(3, N_JOINTS, 4)))
    root = RNG.normal(size=(3, 3))
    joints, rots = forward_kinematics(rest, quats, root)
    tj, tr = forward_kinematics(torch.tensor(rest), torch.tensor(quats), torch.tensor(root))
    assert np.abs(tj.numpy() - joints).max() < 1e-12
    assert np.abs(tr.numpy() - rots).max() < 1e-12
    ta = skinning_transforms(torch.tensor(rest), torch.tensor(quats), torch.tensor(root))
    assert np.abs(ta.numpy() - skinning_transforms(rest, quats, root)).max() < 1e-12


@pytest.mark.parametrize("shape", [(), (7,), (3, 5)])
def test_global_to_local_matches_the_matrix_formula(shape):
    """The compiled kernel against ``q_j = R_parent^T · R_j`` in numpy, for any batch shape."""
    rng = np.random.default_rng(4)
    glob = quat_to_matrix(quat_normalize(rng.normal(size=(*shape, N_JOINTS, 4))))
    twin = glob.copy()
    twin[..., 1:, :, :] = np.swapaxes(glob[..., PARENTS[1:], :, :], -1, -2) @ glob[..., 1:, :, :]
    np.testing.assert_allclose(global_to_local(glob), twin, atol=1e-14)
