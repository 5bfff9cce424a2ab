"""Compiled quaternion ↔ matrix conversions for large float64 batches (numba).

The numpy forms in :mod:`song.geometry.rotations` (their reference twins, and the path for torch and
small batches) build every entry as its own array and stack them: at the motion stage's sizes
(frames × joints) the stacking cost more than the arithmetic.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def quat_to_matrix_kernel(q: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """(N, 3, 3) rotation matrices of unit quaternions (N, 4) wxyz."""
    out = np.empty((q.shape[0], 3, 3))
    for i in range(q.shape[0]):
        w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        out[i, 0, 0], out[i, 0, 1], out[i, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        out[i, 1, 0], out[i, 1, 1], out[i, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        out[i, 2, 0], out[i, 2, 1], out[i, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return out


@numba.njit(cache=True, nogil=True)
def matrix_to_quat_kernel(m: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """(N, 4) unit quaternions (w ≥ 0) of rotation matrices (N, 3, 3): Shepperd's method, best-conditioned branch."""
    out = np.empty((m.shape[0], 4))
    cand = np.empty(4)
    for i in range(m.shape[0]):
        m00, m01, m02 = m[i, 0, 0], m[i, 0, 1], m[i, 0, 2]
        m10, m11, m12 = m[i, 1, 0], m[i, 1, 1], m[i, 1, 2]
        m20, m21, m22 = m[i, 2, 0], m[i, 2, 1], m[i, 2, 2]
        d0, d1 = 1 + m00 + m11 + m22, 1 + m00 - m11 - m22
        d2, d3 = 1 - m00 + m11 - m22, 1 - m00 - m11 + m22
        best, top = 0, d0
        if d1 > top:
            best, top = 1, d1
        if d2 > top:
            best, top = 2, d2
        if d3 > top:
            best, top = 3, d3
        if best == 0:
            cand[0], cand[1], cand[2], cand[3] = d0, m21 - m12, m02 - m20, m10 - m01
        elif best == 1:
            cand[0], cand[1], cand[2], cand[3] = m21 - m12, d1, m10 + m01, m02 + m20
        elif best == 2:
            cand[0], cand[1], cand[2], cand[3] = m02 - m20, m10 + m01, d2, m12 + m21
        else:
            cand[0], cand[1], cand[2], cand[3] = m10 - m01, m20 + m02, m21 + m12, d3
        scale = 2.0 * math.sqrt(max(top, 1e-300))
        for k in range(4):
            cand[k] = cand[k] / scale
        norm = math.sqrt(cand[0] * cand[0] + cand[1] * cand[1] + cand[2] * cand[2] + cand[3] * cand[3])
        if norm == 0.0:
            out[i, 0], out[i, 1], out[i, 2], out[i, 3] = 1.0, 0.0, 0.0, 0.0
            continue
        sign = -1.0 if cand[0] / norm < 0 else 1.0
        for k in range(4):
            out[i, k] = sign * (cand[k] / norm)
    return out
