"""Per-Gaussian, per-frame loop twin of :mod:`song.geometry.lbs` (tests only; slow and plain)."""

from __future__ import annotations

import math

import numpy as np


def _shepperd(m: np.ndarray) -> np.ndarray:
    diag = [1 + m[0, 0] + m[1, 1] + m[2, 2], 1 + m[0, 0] - m[1, 1] - m[2, 2]]
    diag += [1 - m[0, 0] + m[1, 1] - m[2, 2], 1 - m[0, 0] - m[1, 1] + m[2, 2]]
    k = int(np.argmax(diag))
    if k == 0:
        q = [diag[0], m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]
    elif k == 1:
        q = [m[2, 1] - m[1, 2], diag[1], m[1, 0] + m[0, 1], m[0, 2] + m[2, 0]]
    elif k == 2:
        q = [m[0, 2] - m[2, 0], m[1, 0] + m[0, 1], diag[2], m[1, 2] + m[2, 1]]
    else:
        q = [m[1, 0] - m[0, 1], m[2, 0] + m[0, 2], m[2, 1] + m[1, 2], diag[3]]
    norm = math.sqrt(sum(c * c for c in q))
    return np.array([c / norm for c in q])


def _hamilton(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def lbs_reference(
    means: np.ndarray, quats: np.ndarray, indices: np.ndarray, weights: np.ndarray, transforms: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Posed means (F, G, 3) and rotations (F, G, 4) in float64, one Gaussian and frame at a time."""
    n_frames, n = len(transforms), len(means)
    positions = np.zeros((n_frames, n, 3))
    rotations = np.zeros((n_frames, n, 4))
    for f in range(n_frames):
        for g in range(n):
            blend = np.zeros((3, 4))
            for j, w in zip(indices[g], weights[g], strict=True):
                blend += float(w) * transforms[f, int(j)].astype(np.float64)
            positions[f, g] = blend[:, :3] @ means[g].astype(np.float64) + blend[:, 3]
            rotations[f, g] = _hamilton(_shepperd(blend[:, :3]), quats[g].astype(np.float64))
    return positions, rotations
