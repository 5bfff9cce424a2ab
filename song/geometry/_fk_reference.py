"""Plain, obviously-correct twin of :mod:`song.geometry.fk`.

Forward kinematics frame by frame and joint by joint, with rotation matrices built from each quaternion
by the textbook formula.
"""

from __future__ import annotations

import math

import numpy as np

from song.geometry.skeleton import PARENTS


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
    )


def fk_reference(rest: np.ndarray, local_quats: np.ndarray, root_pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``joints (T, 24, 3)`` and ``global_rots (T, 24, 3, 3)`` by explicit loops."""
    n_frames, n_joints = local_quats.shape[:2]
    joints = np.zeros((n_frames, n_joints, 3))
    rots = np.zeros((n_frames, n_joints, 3, 3))
    for f in range(n_frames):
        for j in range(n_joints):
            local = _quat_matrix(local_quats[f, j])
            parent = int(PARENTS[j])
            if parent < 0:
                rots[f, j] = local
                joints[f, j] = root_pos[f]
            else:
                rots[f, j] = rots[f, parent] @ local
                joints[f, j] = joints[f, parent] + rots[f, parent] @ (rest[j] - rest[parent])
    return joints, rots
