"""Analytic two-bone inverse kinematics (hip–knee–ankle, shoulder–elbow–wrist), batched.

The chain ``root → mid → end`` keeps its two bone lengths. The solution puts ``end`` on ``target``
(or as close as the reach allows) with ``mid`` in the plane spanned by the root→target direction and
the ``pole`` vector, on the pole's side: with the body's forward direction as the knee pole a knee
can never bend backwards (hyper-extend). The bend plane normal is ``n = pole × (target − root)``.

Besides the new ``mid``/``end`` positions it returns the two world-space *delta* rotations that carry
the old bones onto the new ones, each built from the orthonormal frame (bone direction, hinge axis),
so applying them to the old global rotations of ``root`` and ``mid`` gives the new global rotations;
with an unchanged target and a pole in the current bend plane both deltas are the identity.
"""

from __future__ import annotations

import numpy as np

from song.geometry.rotations import vector_norm

# Relative slack kept from the fully stretched and fully folded configurations (keeps acos finite).
_REACH_EPS = 1e-6


def _unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    norm = vector_norm(v, keepdims=True)
    out = v / np.where(norm > 1e-12, norm, 1.0)
    if fallback is not None:
        out = np.where(norm > 1e-12, out, fallback)
    return out


def _frame(direction: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(..., 3, 3)`` with columns (direction, hinge ⟂ direction, their cross)."""
    d = _unit(direction)
    h = _unit(hinge - np.sum(hinge * d, axis=-1, keepdims=True) * d)
    return np.stack([d, h, np.cross(d, h)], axis=-1)


def bend_axis(root: np.ndarray, end: np.ndarray, pole: np.ndarray) -> np.ndarray:
    """Unit hinge axes ``(..., 3)``: ``pole × (end − root)`` (fallback: +y where they are parallel)."""
    fallback = np.broadcast_to(np.array([0.0, 1.0, 0.0]), np.broadcast_shapes(root.shape, pole.shape))
    return _unit(np.cross(pole, end - root), fallback)


def two_bone_ik(
    root: np.ndarray,
    mid: np.ndarray,
    end: np.ndarray,
    target: np.ndarray,
    pole: np.ndarray,
    pole_old: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Solve the chain for new ``mid``/``end`` positions and the bone delta rotations.

    Args:
        root: ``(..., 3)`` current root joint positions (bone lengths are taken from the chain), m.
        mid: ``(..., 3)`` current middle joint positions, m.
        end: ``(..., 3)`` current end joint positions, m.
        target: ``(..., 3)`` desired ``end`` position, m.
        pole: ``(..., 3)`` direction the ``mid`` joint should bend towards (e.g. body forward).
        pole_old: pole that describes the *current* bend plane (default ``pole``).

    Returns:
        ``mid_new (..., 3)``, ``end_new (..., 3)`` (equal to ``target`` when reachable),
        ``delta_root (..., 3, 3)`` and ``delta_mid (..., 3, 3)``: world rotations with
        ``R_root_new = delta_root @ R_root_old`` and ``R_mid_new = delta_mid @ R_mid_old``.
    """
    root, mid, end, target, pole = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (root, mid, end, target, pole))
    )
    pole_old = pole if pole_old is None else np.broadcast_to(np.asarray(pole_old, dtype=np.float64), root.shape)
    l1 = vector_norm(mid - root, keepdims=True)
    l2 = vector_norm(end - mid, keepdims=True)
    to_target = target - root
    dist = vector_norm(to_target, keepdims=True)
    d_hat = _unit(to_target, _unit(end - root))
    d = np.clip(dist, np.abs(l1 - l2) * (1 + _REACH_EPS) + 1e-9, (l1 + l2) * (1 - _REACH_EPS))
    cos_a = np.clip((l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d), -1.0, 1.0)
    hinge = bend_axis(root, target, pole)
    towards_pole = np.cross(d_hat, hinge)
    mid_new = root + l1 * (cos_a * d_hat + np.sqrt(1.0 - cos_a * cos_a) * towards_pole)
    end_new = root + d * d_hat
    hinge_old = bend_axis(root, end, pole_old)
    delta_root = _frame(mid_new - root, hinge) @ np.swapaxes(_frame(mid - root, hinge_old), -1, -2)
    delta_mid = _frame(end_new - mid_new, hinge) @ np.swapaxes(_frame(end - mid, hinge_old), -1, -2)
    return mid_new, end_new, delta_root, delta_mid
