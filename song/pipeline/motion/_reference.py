"""Plain, obviously-correct twins of the motion kernels, compared with the vectorised ones in tests.

- :func:`fk_reference`: forward kinematics frame by frame and joint by joint, with rotation
  matrices built from each quaternion by the textbook formula.
- :func:`two_bone_ik_reference`: one chain at a time, by the law of cosines in a hand-built plane.
- :func:`foot_skating_reference`: the GMD skating ratio with explicit loops.
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


def two_bone_ik_reference(
    root: np.ndarray, mid: np.ndarray, end: np.ndarray, target: np.ndarray, pole: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """New ``mid`` and ``end`` of one chain (no batch), by the law of cosines."""
    l1 = float(np.linalg.norm(mid - root))
    l2 = float(np.linalg.norm(end - mid))
    d_vec = target - root
    d = float(np.linalg.norm(d_vec))
    u = d_vec / d
    d = min(max(d, abs(l1 - l2) * (1 + 1e-6) + 1e-9), (l1 + l2) * (1 - 1e-6))
    # the in-plane direction towards the pole: pole minus its component along u
    p = pole - float(np.dot(pole, u)) * u
    p = p / float(np.linalg.norm(p))
    cos_hip = (l1 * l1 + d * d - l2 * l2) / (2 * l1 * d)
    cos_hip = min(1.0, max(-1.0, cos_hip))
    sin_hip = math.sqrt(1.0 - cos_hip * cos_hip)
    mid_new = root + l1 * (cos_hip * u + sin_hip * p)
    return mid_new, root + d * u


def foot_skating_reference(joints: np.ndarray, fps: float, toes: tuple[int, int] = (10, 11)) -> float:
    """GMD skating ratio with loops (see :mod:`song.pipeline.motion.quality`)."""
    n = len(joints)
    if n < 2:
        return 0.0
    count = 0
    for f in range(n - 1):
        skating = False
        for toe in toes:
            # a centred 5-frame mean with edge frames repeated ("nearest")
            window = []
            for g in range(f - 2, f + 3):
                gg = min(max(g, 0), n - 2)
                a, b = joints[gg, toe], joints[gg + 1, toe]
                window.append(math.hypot(b[0] - a[0], b[1] - a[1]) * fps)
            now = window[2]
            low = joints[f, toe, 2] < 0.05 and joints[f + 1, toe, 2] < 0.05
            if low and now > 0.5 and sum(window) / 5 > 0.5:
                skating = True
        count += skating
    return count / n
