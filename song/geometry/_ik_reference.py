"""Plain twin of :func:`song.geometry.ik.two_bone_ik`.

One chain at a time, by the law of cosines in a hand-built plane.
"""

from __future__ import annotations

import math

import numpy as np


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
