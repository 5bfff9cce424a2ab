"""Compiled (numba) posed rotations for :mod:`song.geometry.lbs`, the same definition as its numpy path.

Per Gaussian and frame: blend the 3×3 rotation parts of its top-k joint transforms, take the Shepperd
quaternion (largest candidate, first maximum on ties), normalise, multiply by the canonical rotation.
The numpy path makes ~70 passes over (frames × Gaussians) arrays; this loop keeps everything in
registers, which is what moves full LBS (positions + rotations) past 20 M Gaussian-frames/s on 2 cores.
"""

from __future__ import annotations

import math

import numba
import numpy as np


def _rotations(indices: np.ndarray, weights: np.ndarray, quats: np.ndarray, rots: np.ndarray) -> np.ndarray:
    n_frames, n, k_top = rots.shape[0], indices.shape[0], indices.shape[1]
    out = np.empty((n_frames, n, 4), np.float32)
    for f in range(n_frames):
        for g in range(n):
            m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
            for k in range(k_top):
                w, j = weights[g, k], indices[g, k]
                m00 += w * rots[f, j, 0, 0]
                m01 += w * rots[f, j, 0, 1]
                m02 += w * rots[f, j, 0, 2]
                m10 += w * rots[f, j, 1, 0]
                m11 += w * rots[f, j, 1, 1]
                m12 += w * rots[f, j, 1, 2]
                m20 += w * rots[f, j, 2, 0]
                m21 += w * rots[f, j, 2, 1]
                m22 += w * rots[f, j, 2, 2]
            p, s, q, r = 1.0 + m00, 1.0 - m00, m11 + m22, m11 - m22
            d0, d1, d2, d3 = p + q, p - q, s + r, s - r
            a, b, c = m21 - m12, m02 - m20, m10 - m01
            e1, e2, e3 = m10 + m01, m02 + m20, m12 + m21
            top = max(max(d0, d1), max(d2, d3))
            if d0 == top:
                qw, qx, qy, qz = d0, a, b, c
            elif d1 == top:
                qw, qx, qy, qz = a, d1, e1, e2
            elif d2 == top:
                qw, qx, qy, qz = b, e1, d2, e3
            else:
                qw, qx, qy, qz = c, e2, e3, d3
            norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
            qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
            cw, cx, cy, cz = quats[g, 0], quats[g, 1], quats[g, 2], quats[g, 3]
            out[f, g, 0] = qw * cw - qx * cx - qy * cy - qz * cz
            out[f, g, 1] = qw * cx + qx * cw + qy * cz - qz * cy
            out[f, g, 2] = qw * cy - qx * cz + qy * cw + qz * cx
            out[f, g, 3] = qw * cz + qx * cy - qy * cx + qz * cw
    return out


rotations_kernel = numba.njit(cache=True, nogil=True)(_rotations)
