"""Batched forward kinematics and linear-blend-skinning transforms for the 24-joint skeleton.

Definition (the contract of ``human_amass/traj_{id}/motion.npz``, docs/contracts.md):

- ``R_0 = q_0`` and ``p_0 = root_pos`` (the root's rotation includes the world heading);
- ``R_j = R_parent(j) · q_j`` and ``p_j = p_parent(j) + R_parent(j) · (rest_j − rest_parent(j))``;
- skinning transform ``A_j = [R_j | p_j − R_j · rest_j]`` maps a rest-pose point to the world.

Local rotations ``q_j`` are relative to the rest T-pose (identity everywhere gives the rest pose
translated to ``root_pos``). Joints are processed in index order, which is topological for SMPL
(every parent index is smaller than its child's). numpy arrays, or torch tensors for
:func:`forward_kinematics_matrices` / :func:`forward_kinematics` (same code path).
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from song.geometry.rotations import _xp, quat_to_matrix
from song.geometry.skeleton import PARENTS


def forward_kinematics_matrices(
    rest_joints: Any, local_rots: Any, root_pos: Any, parents: np.ndarray = PARENTS
) -> tuple[Any, Any]:
    """FK from local rotation matrices.

    Args:
        rest_joints: ``(J, 3)`` or ``(..., J, 3)`` rest joint positions, metres (body frame).
        local_rots: ``(..., J, 3, 3)`` parent-local rotations relative to the rest pose.
        root_pos: ``(..., 3)`` world root (pelvis) positions, metres.
        parents: ``(J,)`` parent indices, ``-1`` for the root; parents precede children.

    Returns:
        ``joints (..., J, 3)`` world positions and ``global_rots (..., J, 3, 3)``.
    """
    xp = _xp(local_rots)
    if xp is np:
        return _fk_numpy(np.asarray(rest_joints), np.asarray(local_rots), np.asarray(root_pos), parents)
    n = len(parents)
    offsets = rest_joints[..., 1:, :] - rest_joints[..., parents[1:], :]
    rots: list[Any] = [local_rots[..., 0, :, :]]
    pos: list[Any] = [root_pos + 0 * local_rots[..., 0, :, 0]]
    for j in range(1, n):
        parent = int(parents[j])
        r_parent = rots[parent]
        pos.append(pos[parent] + (r_parent @ offsets[..., j - 1, :, None])[..., 0])
        rots.append(r_parent @ local_rots[..., j, :, :])
    if xp is np:
        return np.stack(pos, axis=-2), np.stack(rots, axis=-3)
    return xp.stack(pos, dim=-2), xp.stack(rots, dim=-3)


@numba.njit(cache=True, nogil=True)
def _fk_kernel(rest, local, root, parents):  # pragma: no cover - compiled
    """(B, J, 3) rest, (B, J, 3, 3) local, (B, 3) root → joints (B, J, 3), global rotations (B, J, 3, 3)."""
    b_count, n = local.shape[0], local.shape[1]
    joints = np.empty((b_count, n, 3))
    rots = np.empty((b_count, n, 3, 3))
    for b in range(b_count):
        rots[b, 0] = local[b, 0]
        joints[b, 0] = root[b]
        for j in range(1, n):
            p = parents[j]
            for r in range(3):
                acc = 0.0
                for c in range(3):
                    acc += rots[b, p, r, c] * (rest[b, j, c] - rest[b, p, c])
                    s = 0.0
                    for k in range(3):
                        s += rots[b, p, r, k] * local[b, j, k, c]
                    rots[b, j, r, c] = s
                joints[b, j, r] = joints[b, p, r] + acc
    return joints, rots


def _fk_numpy(rest_joints: np.ndarray, local_rots: np.ndarray, root_pos: np.ndarray, parents: np.ndarray):
    """:func:`forward_kinematics_matrices` for numpy arrays, compiled.

    numpy's batched 3 × 3 products cost more in dispatch than in arithmetic (FK was the motion stage's
    largest single cost); tests compare it with :mod:`song.geometry._fk_reference` and the torch path.
    """
    batch = local_rots.shape[:-3]
    n = local_rots.shape[-3]
    local = np.ascontiguousarray(local_rots, dtype=np.float64).reshape(-1, n, 3, 3)
    rest = np.ascontiguousarray(np.broadcast_to(rest_joints, (*batch, n, 3)), dtype=np.float64).reshape(-1, n, 3)
    root = np.ascontiguousarray(np.broadcast_to(root_pos, (*batch, 3)), dtype=np.float64).reshape(-1, 3)
    joints, rots = _fk_kernel(rest, local, root, np.asarray(parents, dtype=np.int64))
    return joints.reshape(*batch, n, 3), rots.reshape(*batch, n, 3, 3)


def forward_kinematics(
    rest_joints: Any, local_quats: Any, root_pos: Any, parents: np.ndarray = PARENTS
) -> tuple[Any, Any]:
    """FK from local quaternions (wxyz): see the module docstring.

    Args:
        rest_joints: ``(J, 3)`` or ``(..., J, 3)`` rest joint positions, metres.
        local_quats: ``(..., J, 4)`` unit quaternions (w, x, y, z), parent-local, relative to rest.
        root_pos: ``(..., 3)`` world pelvis positions, metres.
        parents: ``(J,)`` parent indices.

    Returns:
        ``joints (..., J, 3)`` world positions (metres) and ``global_rots (..., J, 3, 3)``.
    """
    return forward_kinematics_matrices(rest_joints, quat_to_matrix(local_quats), root_pos, parents)


def skinning_transforms(rest_joints: Any, local_quats: Any, root_pos: Any, parents: np.ndarray = PARENTS) -> Any:
    """World-from-rest skinning transforms ``A_j = [R_j | p_j − R_j · rest_j]``.

    Args:
        rest_joints: as for :func:`forward_kinematics`.
        local_quats: as for :func:`forward_kinematics`.
        root_pos: as for :func:`forward_kinematics`.
        parents: as for :func:`forward_kinematics`.

    Returns:
        ``(..., J, 3, 4)``: a rest-pose point ``x`` goes to ``A[..., :, :3] @ x + A[..., :, 3]``.
    """
    xp = _xp(local_quats)
    joints, rots = forward_kinematics(rest_joints, local_quats, root_pos, parents)
    trans = joints - (rots @ rest_joints[..., None])[..., 0]
    if xp is np:
        return np.concatenate([rots, trans[..., None]], axis=-1)
    return xp.cat([rots, trans[..., None]], dim=-1)


@numba.njit(cache=True, nogil=True)
def _global_to_local_kernel(glob, parents):  # pragma: no cover - compiled
    """(B, J, 3, 3) global rotations → parent-local ones (the root's unchanged)."""
    b_count, n = glob.shape[0], glob.shape[1]
    local = np.empty_like(glob)
    for b in range(b_count):
        local[b, 0] = glob[b, 0]
        for j in range(1, n):
            p = parents[j]
            for r in range(3):
                for c in range(3):
                    s = 0.0
                    for k in range(3):
                        s += glob[b, p, k, r] * glob[b, j, k, c]
                    local[b, j, r, c] = s
    return local


def global_to_local(global_rots: np.ndarray, parents: np.ndarray = PARENTS) -> np.ndarray:
    """Parent-local rotations ``(..., J, 3, 3)`` from global ones: ``q_j = R_parent^T · R_j``.

    Compiled: numpy's stacked 3 × 3 products spent ~10 ms per pedestrian-minute in dispatch.
    """
    global_rots = np.asarray(global_rots, dtype=np.float64)
    batch, n = global_rots.shape[:-3], global_rots.shape[-3]
    flat = np.ascontiguousarray(global_rots).reshape(-1, n, 3, 3)
    return _global_to_local_kernel(flat, np.asarray(parents, dtype=np.int64)).reshape(*batch, n, 3, 3)
