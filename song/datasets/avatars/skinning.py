"""Skinning-weight transfer: top-4 joint weights from the distance of each point to the skeleton's bones.

A bone is the segment from a joint to one of its children and is driven by that joint (the thigh,
hip → knee, moves with the hip's transform); leaf joints (head, hands, feet) get a short terminal
segment of their own. For a point at distance ``d_j`` from the nearest bone of joint ``j``, the raw
weight is ``exp(−(d_j − d_min) / σ)`` with ``σ = falloff · height``: points next to a joint blend its
two bones, points on a limb follow that limb only (a small σ keeps the inner thighs apart). The weights
are then smoothed by averaging over each point's near neighbours (within ``smooth_radius · height``,
a k-d tree query) and cut to the top 4, renormalised.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

from song.geometry.skeleton import JOINT_INDEX, N_JOINTS, PARENTS

TOP_K = 4
# terminal bones of leaf joints: direction (body frame) and length as fractions of body height
_LEAVES = {
    "head": ((0.0, 0.0, 1.0), 0.12),
    "left_hand": ((0.0, 1.0, 0.0), 0.05),
    "right_hand": ((0.0, -1.0, 0.0), 0.05),
    "left_foot": ((1.0, 0.0, 0.0), 0.05),
    "right_foot": ((1.0, 0.0, 0.0), 0.05),
}


def bone_segments(rest_joints: np.ndarray, height_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bones of a rest skeleton: ``(start (S, 3), end (S, 3), driving joint (S,))``."""
    starts, ends, owners = [], [], []
    for child in range(1, N_JOINTS):
        starts.append(rest_joints[PARENTS[child]])
        ends.append(rest_joints[child])
        owners.append(PARENTS[child])
    for name, (direction, length) in _LEAVES.items():
        joint = JOINT_INDEX[name]
        starts.append(rest_joints[joint])
        ends.append(rest_joints[joint] + np.asarray(direction) * length * height_m)
        owners.append(joint)
    return np.asarray(starts, np.float64), np.asarray(ends, np.float64), np.asarray(owners, np.int64)


@numba.njit(cache=True, nogil=True)
def _bone_distances(points, start, end, owner, n_joints):  # pragma: no cover - compiled
    out = np.full((len(points), n_joints), np.inf)
    for i in range(len(points)):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        for k in range(len(start)):
            ax, ay, az = end[k, 0] - start[k, 0], end[k, 1] - start[k, 1], end[k, 2] - start[k, 2]
            rx, ry, rz = px - start[k, 0], py - start[k, 1], pz - start[k, 2]
            t = min(max((rx * ax + ry * ay + rz * az) / max(ax * ax + ay * ay + az * az, 1e-12), 0.0), 1.0)
            dx, dy, dz = rx - t * ax, ry - t * ay, rz - t * az
            d = np.sqrt(dx * dx + dy * dy + dz * dz)
            if d < out[i, owner[k]]:
                out[i, owner[k]] = d
    return out


@numba.njit(cache=True, nogil=True)
def _neighbour_mean(raw, idx, valid):  # pragma: no cover - compiled
    out = np.zeros_like(raw)
    for i in range(raw.shape[0]):
        count = 0
        for j in range(idx.shape[1]):
            if valid[i, j]:
                count += 1
                row = idx[i, j]
                for c in range(raw.shape[1]):
                    out[i, c] += raw[row, c]
        for c in range(raw.shape[1]):
            out[i, c] /= count
    return out


def joint_distances(points: np.ndarray, rest_joints: np.ndarray, height_m: float) -> np.ndarray:
    """(N, 24) distance (m) from each point to the nearest bone driven by each joint (inf if none).

    Compiled (numba): a point-by-bone loop; numpy needed (N, bones, 3) temporaries and was the
    largest cost of building an avatar.
    """
    start, end, owner = bone_segments(rest_joints, height_m)
    return _bone_distances(np.ascontiguousarray(points, np.float64), start, end, owner, N_JOINTS)


def top_k(weights: np.ndarray, k: int = TOP_K) -> tuple[np.ndarray, np.ndarray]:
    """Keep the ``k`` largest weights per row (descending, ties by joint index), renormalised."""
    order = np.argsort(-weights, axis=1, kind="stable")[:, :k]
    kept = np.take_along_axis(weights, order, axis=1)
    kept = kept / np.maximum(kept.sum(axis=1, keepdims=True), 1e-12)
    return order.astype(np.uint8), kept.astype(np.float32)


def transfer_weights(
    points: np.ndarray,
    rest_joints: np.ndarray,
    height_m: float,
    falloff: float = 0.006,
    smooth_radius: float = 0.012,
    neighbours: int = 8,
) -> tuple[np.ndarray, np.ndarray]:
    """Top-4 skinning weights for points around a rest skeleton.

    Args:
        points: (N, 3) rest-pose positions, metres, in the skeleton's frame.
        rest_joints: (24, 3) rest skeleton, metres.
        height_m: body height, metres (sets the falloff and smoothing scales).
        falloff: σ as a fraction of the height.
        smooth_radius: neighbour radius for smoothing, as a fraction of the height (0 disables).
        neighbours: at most this many neighbours (the point included) are averaged.

    Returns:
        ``indices (N, 4) uint8`` and ``weights (N, 4) float32`` (descending, rows sum to 1).
    """
    points = np.asarray(points, np.float64)
    dist = joint_distances(points, np.asarray(rest_joints, np.float64), height_m)
    raw = np.exp(-(dist - dist.min(axis=1, keepdims=True)) / (falloff * height_m)).astype(np.float32)
    raw /= raw.sum(axis=1, keepdims=True)
    if smooth_radius > 0 and len(points) > 1:
        k = min(neighbours, len(points))
        # both cores: the neighbour search is the largest single cost of building an avatar
        d, idx = cKDTree(points).query(points, k=k, distance_upper_bound=smooth_radius * height_m, workers=2)
        valid = np.isfinite(d)
        idx = np.where(valid, idx, np.arange(len(points))[:, None])
        raw = _neighbour_mean(raw, idx.astype(np.int64), valid)
    return top_k(raw)
