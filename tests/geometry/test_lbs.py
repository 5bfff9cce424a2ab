"""Batched LBS against the per-Gaussian reference loop, numpy and torch, plus exact special cases."""

from __future__ import annotations

import numpy as np
import pytest

from song.geometry._lbs_reference import lbs_reference
from song.geometry.fk import skinning_transforms
from song.geometry.lbs import SkinnedGaussians, lbs, lbs_positions, shepperd_quat
from song.geometry.rotations import matrix_to_quat, quat_normalize, quat_to_matrix
from song.geometry.skeleton import rest_joints


def _random_case(seed: int, n: int = 200, frames: int = 3):
    rng = np.random.default_rng(seed)
    height = rng.uniform(1.5, 1.95)
    rest = rest_joints(height) + rng.normal(0, 0.02, (24, 3))  # random skeleton proportions
    means = (rest[rng.integers(0, 24, n)] + rng.normal(0, 0.08, (n, 3))).astype(np.float32)
    quats = quat_normalize(rng.normal(size=(n, 4))).astype(np.float32)
    indices = np.stack([rng.choice(24, 4, replace=False) for _ in range(n)])
    weights = rng.dirichlet(np.ones(4) * 0.7, size=n).astype(np.float32)
    local = quat_normalize(np.concatenate([np.ones((frames, 24, 1)), rng.normal(0, 0.5, (frames, 24, 3))], axis=-1))
    root = rng.normal(0, 3.0, (frames, 3))
    transforms = skinning_transforms(rest, local, root).astype(np.float32)
    return means, quats, indices, weights, transforms


def _aligned(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.where((a * b).sum(-1, keepdims=True) < 0, -a, a)


@pytest.mark.parametrize("seed", range(4))
def test_numpy_matches_reference(seed: int) -> None:
    means, quats, indices, weights, transforms = _random_case(seed)
    positions, rotations = lbs(SkinnedGaussians.build(means, quats, indices, weights), transforms)
    ref_pos, ref_rot = lbs_reference(means, quats, indices, weights, transforms)
    # float32 arithmetic on coordinates up to ~10 m: compare relative to the root offset
    assert np.abs(positions - ref_pos).max() <= 1e-5 * max(1.0, np.abs(ref_pos).max())
    assert np.abs(_aligned(rotations, ref_rot) - ref_rot).max() <= 1e-5


def test_torch_matches_numpy_and_single_frame() -> None:
    torch = pytest.importorskip("torch")
    means, quats, indices, weights, transforms = _random_case(7)
    skin = SkinnedGaussians.build(means, quats, indices, weights)
    positions, rotations = lbs(skin, transforms)
    t_pos, t_rot = lbs(skin.to_torch(), torch.from_numpy(transforms))
    assert np.abs(t_pos.numpy() - positions).max() <= 1e-5 * np.abs(positions).max()
    assert np.abs(_aligned(t_rot.numpy(), rotations) - rotations).max() <= 1e-5
    single = lbs_positions(skin, transforms[1])
    assert single.shape == (len(means), 3)
    np.testing.assert_allclose(single, positions[1], atol=1e-6)


def test_cuda_matches_numpy_in_one_block() -> None:
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device")
    means, quats, indices, weights, transforms = _random_case(8, n=500, frames=40)  # pragma: no cover
    skin = SkinnedGaussians.build(means, quats, indices, weights)
    positions, rotations = lbs(skin, transforms)
    t_pos, t_rot = lbs(skin.to_torch("cuda"), torch.from_numpy(transforms).cuda())
    assert np.abs(t_pos.cpu().numpy() - positions).max() <= 1e-5 * np.abs(positions).max()
    assert np.abs(_aligned(t_rot.cpu().numpy(), rotations) - rotations).max() <= 1e-5


def test_rest_pose_is_identity_and_rigid_binding_is_rigid() -> None:
    means, quats, indices, weights, _ = _random_case(3, frames=1)
    rest = rest_joints(1.7)
    identity = skinning_transforms(rest, np.tile([1.0, 0, 0, 0], (24, 1)), rest[0]).astype(np.float32)
    skin = SkinnedGaussians.build(means, quats, indices, weights)
    positions, rotations = lbs(skin, identity)
    np.testing.assert_allclose(positions, means, atol=1e-6)
    np.testing.assert_allclose(_aligned(rotations, quats), quats, atol=1e-6)
    # every Gaussian bound to joint 5 only: posed = A_5 applied rigidly, rotation = R_5 ⊗ q
    rng = np.random.default_rng(0)
    local = quat_normalize(rng.normal(size=(24, 4)))
    transforms = skinning_transforms(rest, local, np.array([1.0, 2.0, 0.9])).astype(np.float32)
    rigid = SkinnedGaussians.build(means, quats, np.full((len(means), 1), 5), np.ones((len(means), 1)))
    positions, rotations = lbs(rigid, transforms)
    np.testing.assert_allclose(positions, means @ transforms[5, :, :3].T + transforms[5, :, 3], atol=2e-5)
    expected = quat_to_matrix(rotations.astype(np.float64))
    np.testing.assert_allclose(expected, transforms[5, :, :3] @ quat_to_matrix(quats.astype(np.float64)), atol=1e-5)


def test_shepperd_matches_rotation_quaternions() -> None:
    rng = np.random.default_rng(1)
    q = quat_normalize(rng.normal(size=(500, 4)))
    m = quat_to_matrix(q)
    np.testing.assert_allclose(_aligned(shepperd_quat(m), q), q, atol=1e-12)
    np.testing.assert_allclose(_aligned(shepperd_quat(m), matrix_to_quat(m)), matrix_to_quat(m), atol=1e-12)


def test_compiled_rotations_match_the_numpy_path() -> None:
    """The numba loop and the blocked numpy extraction compute the same definition."""
    from song.geometry.lbs import lbs_rotations

    means, quats, indices, weights, transforms = _random_case(11, n=500, frames=4)
    skin = SkinnedGaussians.build(means, quats, indices, weights)
    compiled = lbs_rotations(skin, transforms)
    blocked = lbs_rotations(skin, transforms, block=1 << 12)
    np.testing.assert_allclose(_aligned(compiled, blocked), blocked, atol=1e-5)
    single = lbs_rotations(skin, transforms[2])
    np.testing.assert_allclose(_aligned(single, compiled[2]), compiled[2], atol=1e-6)
