"""Batched rotations: unit quaternions (w, x, y, z), axis-angle, 3×3 matrices and the 6-D representation.

Conventions (used everywhere in SONG):

- Quaternions are **scalar first** ``(w, x, y, z)``, Hamilton product, active rotations: ``q ⊗ v ⊗ q*``
  rotates the vector ``v``. ``q`` and ``-q`` are the same rotation; functions that return quaternions
  return the representative with ``w ≥ 0`` unless they say otherwise.
- Matrices act on column vectors: ``v' = R @ v``; composition ``R_a @ R_b`` applies ``R_b`` first,
  matching ``quat_mul(q_a, q_b)``.
- Axis-angle is a 3-vector ``θ·n`` (radians), as in SMPL/AMASS ``poses``.
- The 6-D representation (Zhou et al. 2019) is the first two **columns** of the matrix, concatenated
  as ``(r00, r10, r20, r01, r11, r21)``.

All functions take arrays with any leading batch shape ``(...)``. Most are numpy-only (float64 in,
float64 out unless the input is float32); :func:`quat_mul`, :func:`quat_conj`, :func:`quat_rotate`
and :func:`quat_to_matrix` also accept torch tensors (imported lazily, only if given one).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

# Below this angle (radians) the axis-angle ↔ quaternion maps use their Taylor expansions.
_SMALL_ANGLE = 1e-6


def _xp(array: Any) -> Any:
    """numpy, or torch when ``array`` is a torch tensor (torch is never imported otherwise)."""
    if type(array).__module__.startswith("torch"):
        import torch

        return torch
    return np


def _stack(xp: Any, items: list, axis: int = -1) -> Any:
    return xp.stack(items, axis) if xp is np else xp.stack(items, dim=axis)


def vector_norm(v: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """Euclidean length along the last axis (numpy arrays).

    About twice as quick as ``np.linalg.norm(v, axis=-1)`` on the long stacks of 3- and 4-vectors that
    motion code normalises (the motion stage called it ~200 times per pedestrian).
    """
    v = np.asarray(v)
    length = np.sqrt(np.einsum("...i,...i->...", v, v))
    return length[..., None] if keepdims else length


def quat_identity(shape: tuple[int, ...] = (), dtype: Any = np.float64) -> np.ndarray:
    """Identity quaternions of the given batch shape: ``(*shape, 4)``."""
    q = np.zeros((*shape, 4), dtype=dtype)
    q[..., 0] = 1.0
    return q


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)``; a zero quaternion becomes the identity."""
    q = np.asarray(q)
    norm = vector_norm(q, keepdims=True)
    out = q / np.where(norm > 0, norm, 1.0)
    zero = norm[..., 0] == 0
    if np.any(zero):
        out = out.copy()
        out[zero] = (1.0, 0.0, 0.0, 0.0)
    return out


def quat_positive(q: np.ndarray) -> np.ndarray:
    """The representative with ``w ≥ 0`` of each quaternion ``(..., 4)``."""
    q = np.asarray(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_conj(q: Any) -> Any:
    """Conjugate ``(w, -x, -y, -z)``: the inverse of a unit quaternion. numpy or torch."""
    xp = _xp(q)
    return _stack(xp, [q[..., 0], -q[..., 1], -q[..., 2], -q[..., 3]])


def quat_mul(a: Any, b: Any) -> Any:
    """Hamilton product ``a ⊗ b`` (apply ``b`` first), broadcasting ``(..., 4)``. numpy or torch."""
    xp = _xp(a)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return _stack(
        xp,
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
    )


def quat_rotate(q: Any, v: Any) -> Any:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)`` (broadcasting). numpy or torch."""
    xp = _xp(q)
    w = q[..., :1]
    u = q[..., 1:]
    cross = xp.cross(u, v, axis=-1) if xp is np else xp.cross(*xp.broadcast_tensors(u, v), dim=-1)
    cross2 = xp.cross(u, cross, axis=-1) if xp is np else xp.cross(*xp.broadcast_tensors(u, cross), dim=-1)
    return v + 2.0 * (w * cross + cross2)


COMPILED_MIN = 256  # from this many rotations a float64 numpy batch goes through the compiled kernels


def _compiled(array: Any, item_shape: tuple[int, ...]) -> bool:
    """Whether ``array`` is a numpy float64 batch big enough for :mod:`song.geometry._rotations_kernel`."""
    return (
        isinstance(array, np.ndarray)
        and array.dtype == np.float64
        and array.shape[len(array.shape) - len(item_shape) :] == item_shape
        and array.size >= COMPILED_MIN * int(np.prod(item_shape))
    )


def quat_to_matrix(q: Any) -> Any:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)``. numpy or torch."""
    if _compiled(q, (4,)):
        from song.geometry._rotations_kernel import quat_to_matrix_kernel

        return quat_to_matrix_kernel(np.ascontiguousarray(q).reshape(-1, 4)).reshape(*q.shape[:-1], 3, 3)
    xp = _xp(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        _stack(xp, [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
        _stack(xp, [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
        _stack(xp, [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
    ]
    return _stack(xp, rows, axis=-2)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` (``w ≥ 0``) of rotation matrices ``(..., 3, 3)``.

    Branch-free variant of Shepperd's method: all four candidate quaternions are formed and, per
    matrix, the one with the largest (hence best-conditioned) component is kept.
    """
    m = np.asarray(m)
    if _compiled(m, (3, 3)):
        from song.geometry._rotations_kernel import matrix_to_quat_kernel

        return matrix_to_quat_kernel(np.ascontiguousarray(m).reshape(-1, 3, 3)).reshape(*m.shape[:-2], 4)
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    diag = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    # candidate k has its k-th component equal to sqrt(diag_k)/2; the rest follow from off-diagonals
    cand = np.stack(
        [
            np.stack([diag[..., 0], m21 - m12, m02 - m20, m10 - m01], -1),
            np.stack([m21 - m12, diag[..., 1], m10 + m01, m02 + m20], -1),
            np.stack([m02 - m20, m10 + m01, diag[..., 2], m12 + m21], -1),
            np.stack([m10 - m01, m20 + m02, m21 + m12, diag[..., 3]], -1),
        ],
        -2,
    )
    best = np.argmax(diag, axis=-1)
    chosen = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    scale = np.sqrt(np.maximum(np.take_along_axis(diag, best[..., None], axis=-1), 1e-300))
    return quat_positive(quat_normalize(chosen / (2.0 * scale)))


def axis_angle_to_quat(aa: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` of axis-angle vectors ``(..., 3)`` (radians)."""
    aa = np.asarray(aa, dtype=np.result_type(aa, np.float32))
    angle = vector_norm(aa, keepdims=True)
    half = 0.5 * angle
    small = angle < _SMALL_ANGLE
    # sin(θ/2)/θ → 1/2 − θ²/48 for small θ
    k = np.where(small, 0.5 - angle * angle / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), aa * k], axis=-1)


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """Axis-angle vectors ``(..., 3)`` with angle in ``[0, π]`` of unit quaternions ``(..., 4)``."""
    q = quat_positive(np.asarray(q))
    sin_half = vector_norm(q[..., 1:], keepdims=True)
    angle = 2.0 * np.arctan2(sin_half, q[..., :1])
    small = sin_half < _SMALL_ANGLE
    # θ/sin(θ/2) → 2/w (1 + ...) for small angles; 2/w is exact to first order
    k = np.where(small, 2.0 / np.maximum(q[..., :1], 1e-12), angle / np.where(small, 1.0, sin_half))
    return q[..., 1:] * k


def axis_angle_to_matrix(aa: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of axis-angle vectors ``(..., 3)``."""
    return quat_to_matrix(axis_angle_to_quat(aa))


def matrix_to_axis_angle(m: np.ndarray) -> np.ndarray:
    """Axis-angle vectors ``(..., 3)`` of rotation matrices ``(..., 3, 3)``."""
    return quat_to_axis_angle(matrix_to_quat(m))


def matrix_to_6d(m: np.ndarray) -> np.ndarray:
    """6-D representation ``(..., 6)``: the first two columns of ``(..., 3, 3)``."""
    m = np.asarray(m)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_to_matrix(d6: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from 6-D vectors by Gram-Schmidt (any non-degenerate input)."""
    d6 = np.asarray(d6)
    a, b = d6[..., :3], d6[..., 3:]
    c0 = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b - np.sum(c0 * b, axis=-1, keepdims=True) * c0
    c1 = b / np.linalg.norm(b, axis=-1, keepdims=True)
    c2 = np.cross(c0, c1)
    return np.stack([c0, c1, c2], axis=-1)


def quat_about_axis(axis: np.ndarray | tuple[float, float, float], angle: np.ndarray | float) -> np.ndarray:
    """Quaternions ``(..., 4)`` rotating by ``angle (...)`` radians about the unit ``axis (3,)``."""
    axis = np.asarray(axis, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    half = 0.5 * angle[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def quat_about_z(yaw: np.ndarray | float) -> np.ndarray:
    """Quaternions ``(..., 4)`` of yaw rotations (radians, CCW about +z)."""
    return quat_about_axis((0.0, 0.0, 1.0), yaw)


def rot_x(angle: np.ndarray | float) -> np.ndarray:
    """Matrices ``(..., 3, 3)`` of rotations about +x by ``angle`` radians."""
    return quat_to_matrix(quat_about_axis((1.0, 0.0, 0.0), angle))


def rot_y(angle: np.ndarray | float) -> np.ndarray:
    """Matrices ``(..., 3, 3)`` of rotations about +y by ``angle`` radians."""
    return quat_to_matrix(quat_about_axis((0.0, 1.0, 0.0), angle))


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """Matrices ``(..., 3, 3)`` of rotations about +z by ``angle`` radians."""
    return quat_to_matrix(quat_about_z(angle))


def yaw_of_matrix(m: np.ndarray) -> np.ndarray:
    """Heading ``(...)`` radians of rotations ``(..., 3, 3)``: the yaw of the rotated +x axis."""
    m = np.asarray(m)
    return np.arctan2(m[..., 1, 0], m[..., 0, 0])


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle ``(...)`` radians of the relative rotation between unit quaternions ``a`` and ``b``."""
    dot = np.abs(np.sum(np.asarray(a) * np.asarray(b), axis=-1))
    return 2.0 * np.arccos(np.clip(dot, -1.0, 1.0))


def quat_slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation along the shorter arc, broadcasting ``(..., 4)`` and ``t (...)``.

    Returns unit quaternions; ``t = 0`` gives ``a`` and ``t = 1`` gives ``b`` (or ``-b``).
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-6
    safe = np.where(near, 1.0, sin_theta)
    wa = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(near, t, np.sin(t * theta) / safe)
    return quat_normalize(wa * a + wb * b)


def quat_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so that consecutive quaternions have a non-negative dot product.

    Needed before any linear filtering of quaternion sequences (``q`` and ``-q`` are one rotation).
    """
    q = np.moveaxis(np.asarray(q, dtype=np.float64), axis, 0).copy()
    if len(q) > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        flips = np.cumsum(dots < 0, axis=0) % 2 == 1
        q[1:] = np.where(flips[..., None], -q[1:], q[1:])
    return np.moveaxis(q, 0, axis)


def smooth_quats(q: np.ndarray, sigma_frames: float, axis: int = 0) -> np.ndarray:
    """Quaternion-aware Gaussian smoothing of rotation sequences along ``axis`` (time).

    Signs are made continuous first, then each component is Gaussian-filtered (``mode="nearest"``)
    and the result renormalised: a weighted chordal mean, which is the rotation average to second
    order for the small spreads inside a smoothing window.

    Args:
        q: ``(..., 4)`` unit quaternions with time along ``axis``.
        sigma_frames: Gaussian standard deviation in frames (``0`` returns a copy).
        axis: the time axis of ``q``.

    Returns:
        Unit quaternions, same shape, ``w ≥ 0`` not enforced (signs stay continuous).
    """
    from scipy.ndimage import gaussian_filter1d

    q = quat_continuous(q, axis=axis)
    if sigma_frames <= 0 or q.shape[axis] < 2:
        return q
    return quat_normalize(gaussian_filter1d(q, sigma_frames, axis=axis, mode="nearest"))


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Angles wrapped to ``[-π, π)``; a float stays a float (the one rule; compiled kernels inline it).

    A Python float takes plain float arithmetic (bit for bit numpy's result, ~20× faster than a 0-d
    array; the gait's per-frame loop calls this ~1,500 times per pedestrian).
    """
    if isinstance(angle, float | int):
        return (float(angle) + math.pi) % (2.0 * math.pi) - math.pi
    wrapped = (np.asarray(angle, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi
    return float(wrapped) if np.ndim(angle) == 0 else wrapped
