"""Two-bone IK: reach, bone lengths, pole side, delta rotations, and the per-chain twin."""

from __future__ import annotations

import numpy as np
import pytest

from song.geometry._ik_reference import two_bone_ik_reference
from song.geometry.ik import two_bone_ik

RNG = np.random.default_rng(11)


def _chains(n: int) -> tuple[np.ndarray, ...]:
    root = RNG.normal(size=(n, 3))
    mid = root + np.array([0.02, 0.0, -0.42]) + RNG.normal(scale=0.02, size=(n, 3))
    end = mid + np.array([-0.02, 0.0, -0.40]) + RNG.normal(scale=0.02, size=(n, 3))
    target = root + RNG.normal(scale=0.35, size=(n, 3)) + np.array([0.0, 0.0, -0.4])
    pole = np.array([1.0, 0.0, 0.0]) + RNG.normal(scale=0.2, size=(n, 3))
    return root, mid, end, target, pole


def test_matches_per_chain_twin():
    root, mid, end, target, pole = _chains(200)
    mid_new, end_new, _, _ = two_bone_ik(root, mid, end, target, pole)
    for i in range(200):
        ref_mid, ref_end = two_bone_ik_reference(root[i], mid[i], end[i], target[i], pole[i])
        assert np.abs(mid_new[i] - ref_mid).max() < 1e-9
        assert np.abs(end_new[i] - ref_end).max() < 1e-9


def test_reaches_reachable_targets_and_keeps_bone_lengths():
    root, mid, end, target, pole = _chains(300)
    l1 = np.linalg.norm(mid - root, axis=1)
    l2 = np.linalg.norm(end - mid, axis=1)
    mid_new, end_new, d_root, d_mid = two_bone_ik(root, mid, end, target, pole)
    dist = np.linalg.norm(target - root, axis=1)
    reachable = (dist < 0.999 * (l1 + l2)) & (dist > 1.001 * np.abs(l1 - l2))
    assert reachable.sum() > 100
    assert np.abs(end_new - target)[reachable].max() < 1e-9
    assert np.allclose(np.linalg.norm(mid_new - root, axis=1), l1)
    assert np.allclose(np.linalg.norm(end_new - mid_new, axis=1), l2)
    # unreachable targets: the chain stretches straight towards them
    far = dist > (l1 + l2)
    direction = (target - root) / dist[:, None]
    assert np.allclose(((end_new - root) / np.linalg.norm(end_new - root, axis=1)[:, None])[far], direction[far])
    # the delta rotations carry the old bones onto the new ones and are proper rotations
    assert np.allclose((d_root @ (mid - root)[..., None])[..., 0], mid_new - root, atol=1e-12)
    assert np.allclose((d_mid @ (end - mid)[..., None])[..., 0], end_new - mid_new, atol=1e-12)
    assert np.allclose(np.linalg.det(d_root), 1.0) and np.allclose(np.linalg.det(d_mid), 1.0)


def test_mid_joint_bends_towards_the_pole():
    root, mid, end, target, pole = _chains(300)
    mid_new, end_new, _, _ = two_bone_ik(root, mid, end, target, pole)
    axis = (end_new - root) / np.linalg.norm(end_new - root, axis=1, keepdims=True)
    offset = (mid_new - root) - np.sum((mid_new - root) * axis, axis=1, keepdims=True) * axis
    assert np.all(np.sum(offset * pole, axis=1) >= -1e-9)


def test_unchanged_target_with_in_plane_pole_is_identity():
    root, mid, end, _, _ = _chains(50)
    axis = (end - root) / np.linalg.norm(end - root, axis=1, keepdims=True)
    pole = (mid - root) - np.sum((mid - root) * axis, axis=1, keepdims=True) * axis
    mid_new, end_new, d_root, d_mid = two_bone_ik(root, mid, end, end, pole)
    assert np.abs(mid_new - mid).max() < 1e-9
    assert np.abs(d_root - np.eye(3)).max() < 1e-9
    assert np.abs(d_mid - np.eye(3)).max() < 1e-9


@pytest.mark.parametrize("shape", [(3,), (4, 5, 3)])
def test_batch_shapes(shape):
    root = np.zeros(shape)
    mid = root + [0, 0, -0.4]
    end = root + [0, 0, -0.8]
    out = two_bone_ik(root, mid, end, root + [0.2, 0.0, -0.6], np.broadcast_to([1.0, 0, 0], shape))
    assert out[0].shape == shape and out[2].shape == (*shape[:-1], 3, 3)
