"""AMASS export of a motion: SMPL-H ``poses (T, 156)`` layout plus the SMPL-X spellings.

Frame and conventions (written to ``meta.json`` under ``amass`` as well):

- **World**: SONG's world frame, Z up, metres, floor at z = 0 (AMASS's own convention is Z up too).
- **Body-native frame**: SMPL's rest pose faces +Z with Y up and the body's left on +X. Our skeleton's
  body frame is x forward, y left, z up. ``C`` (columns = SMPL X, Y, Z in our body frame) is the
  change of basis ``v_ours = C · v_smpl``; joint ``j > 0`` rotations are conjugated
  ``q_smpl = Cᵀ q_ours C`` and the root becomes ``root_orient = q_ours,0 · C`` (world-from-SMPL-native),
  so a real SMPL-H body driven by these parameters faces the same way as our skeleton.
- **Translation** (AMASS's convention): an SMPL-family body posed with ``root_orient`` rotates about
  its rest pelvis ``J0`` (model coordinates) and is then shifted by ``trans``, so its pelvis lands at
  ``J0 + trans`` whatever the root orientation. ``J0`` is the model's pelvis at zero betas:
  ``SMPL_PELVIS_J0`` below, the SMPL neutral model's joint regressor applied to its template (the
  model's origin is near the navel, its soles about 1.2 m below). We write
  ``trans = root_pos − SMPL_PELVIS_J0``, so a neutral SMPL/SMPL-H body at zero betas puts its pelvis on
  our pelvis. A consumer with another model or shape (pelvis ``J0'`` from its own regressor) adds
  ``SMPL_PELVIS_J0 − J0'`` to ``trans``; ``meta.json`` records the ``J0`` used. (Until 0.1 of this
  module ``J0`` was our own rest pelvis, ``(0, pelvis height, 0)``: an SMPL body landed ~1.1 m high.)
- **Joints**: SMPL-H has 52 joints: 22 body joints (our 0–21, same order) and 2 × 15 finger joints
  (left then right; per hand index1-3, middle1-3, pinky1-3, ring1-3, thumb1-3). Our joints 22/23
  (``left_hand``/``right_hand``) are SMPL's hand end points at the middle-finger knuckle; their
  rotations go to SMPL-H ``left_middle1``/``right_middle1`` (joints 25 and 40), the joints sitting at
  that knuckle, so nothing is lost; every other finger value is zero (flat hand).
- ``poses = [root_orient (3) | pose_body (63) | pose_hand (90)]`` axis-angle radians; ``betas`` are 16
  zeros (body shape is given by our rest skeleton and ``meta.json``'s height), ``gender`` "neutral".
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.limits import read_npz
from song.errors import FormatError
from song.geometry.rotations import (
    axis_angle_to_quat,
    matrix_to_quat,
    quat_mul,
    quat_to_axis_angle,
)
from song.util import write_npz_compressed_atomic

# v_ours = C · v_smpl: SMPL +X (left) → our +y, SMPL +Y (up) → our +z, SMPL +Z (forward) → our +x
C_SMPL_TO_BODY = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
_QC = matrix_to_quat(C_SMPL_TO_BODY)
_QC_INV = _QC * np.array([1.0, -1.0, -1.0, -1.0])
N_BODY = 22  # SMPL-H body joints incl. the root
HAND_SLOTS = {22: 25, 23: 40}  # our left_hand/right_hand → SMPL-H left_middle1/right_middle1
N_BETAS = 16
AMASS_KEYS = (
    "poses",
    "trans",
    "betas",
    "gender",
    "mocap_framerate",
    "root_orient",
    "pose_body",
    "pose_hand",
    "mocap_frame_rate",
    "mocap_time_length",
    "surface_model_type",
    "num_betas",
)


# the SMPL neutral model's rest pelvis at zero betas, model coordinates (Y up, +Z forward), metres:
# J_regressor · v_template of SMPL (Loper et al., SIGGRAPH Asia 2015), as tabulated by SMPL tool chains
SMPL_PELVIS_J0 = np.array([-0.001795, -0.223333, 0.028219])


def pelvis_j0() -> np.ndarray:
    """``J0 (3,)``: the rest pelvis that ``trans`` is measured from (``SMPL_PELVIS_J0``; module docstring)."""
    return SMPL_PELVIS_J0.copy()


def to_amass(local_quats: np.ndarray, root_pos: np.ndarray, fps: float) -> dict[str, Any]:
    """AMASS arrays of a motion.

    Args:
        local_quats: ``(T, 24, 4)`` wxyz, our body frame (see :mod:`song.geometry.fk`).
        root_pos: ``(T, 3)`` world pelvis, metres.
        fps: frame rate, Hz.

    Returns:
        Dict with the SMPL-H and SMPL-X keys (float64 arrays; ``gender`` a 0-d string array).
    """
    q = np.asarray(local_quats, dtype=np.float64)
    n = len(q)
    smpl = np.empty_like(q)
    smpl[:, 0] = quat_mul(q[:, 0], _QC)
    smpl[:, 1:] = quat_mul(quat_mul(_QC_INV, q[:, 1:]), _QC)
    aa = quat_to_axis_angle(smpl)
    poses = np.zeros((n, 52, 3))
    poses[:, :N_BODY] = aa[:, :N_BODY]
    for ours, slot in HAND_SLOTS.items():
        poses[:, slot] = aa[:, ours]
    poses = poses.reshape(n, 156)
    trans = np.asarray(root_pos, dtype=np.float64) - pelvis_j0()
    return {
        "poses": poses,
        "trans": trans,
        "betas": np.zeros(N_BETAS),
        "gender": np.array("neutral"),
        "mocap_framerate": np.array(float(fps)),
        "root_orient": poses[:, :3].copy(),
        "pose_body": poses[:, 3:66].copy(),
        "pose_hand": poses[:, 66:].copy(),
        "mocap_frame_rate": np.array(float(fps)),
        "mocap_time_length": np.array(n / float(fps)),
        "surface_model_type": np.array("smplh"),
        "num_betas": np.array(N_BETAS),
    }


def write_amass(path: str | Path, amass: dict[str, Any]) -> None:
    """Write the arrays of :func:`to_amass` atomically as a deflated ``.npz`` (about 5× smaller; np.load reads it)."""
    write_npz_compressed_atomic(path, **{key: amass[key] for key in AMASS_KEYS})


def read_amass(path: str | Path) -> dict[str, np.ndarray]:
    """Read an AMASS ``.npz`` (SMPL-H ``poses`` or SMPL-X ``root_orient``/``pose_body``/``pose_hand``)."""
    out = read_npz(path)
    if "poses" not in out:
        if not {"root_orient", "pose_body"} <= out.keys():
            raise FormatError(path, "poses", "neither SMPL-H poses nor SMPL-X root_orient/pose_body present")
        n = len(out["root_orient"])
        hand = out.get("pose_hand", np.zeros((n, 90)))
        out["poses"] = np.concatenate([out["root_orient"], out["pose_body"], hand], axis=1)
    if out["poses"].ndim != 2 or out["poses"].shape[1] != 156 or "trans" not in out:
        raise FormatError(path, "poses", f"expected (T, 156) poses and trans, got {out['poses'].shape}")
    return out


def from_amass(amass: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Decode AMASS arrays back to our ``local_quats (T, 24, 4)`` (w ≥ 0) and ``root_pos (T, 3)``."""
    poses = np.asarray(amass["poses"], dtype=np.float64)
    n = len(poses)
    aa = poses.reshape(n, 52, 3)
    ours_aa = np.zeros((n, 24, 3))
    ours_aa[:, :N_BODY] = aa[:, :N_BODY]
    for ours, slot in HAND_SLOTS.items():
        ours_aa[:, ours] = aa[:, slot]
    smpl = axis_angle_to_quat(ours_aa)
    q = np.empty_like(smpl)
    q[:, 0] = quat_mul(smpl[:, 0], _QC_INV)
    q[:, 1:] = quat_mul(quat_mul(_QC, smpl[:, 1:]), _QC_INV)
    q = np.where(q[..., :1] < 0, -q, q)
    root = np.asarray(amass["trans"], dtype=np.float64) + pelvis_j0()
    return q, root
