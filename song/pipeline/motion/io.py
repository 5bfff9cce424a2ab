"""``human_amass/traj_{id}/``: ``motion.npz`` (our skeleton), ``motion_amass.npz`` (AMASS), ``meta.json``.

``motion.npz`` (the contract in docs/contracts.md): ``t`` (T,) float64 s; ``frame`` (T,) int32;
``height_m`` () float64; ``rest_joints`` (24, 3) float32; ``local_quats`` (T, 24, 4) float32 wxyz;
``root_pos`` (T, 3) float32; ``joints`` (T, 24, 3) float32 = FK(rest_joints, local_quats, root_pos)
computed from the stored float32 values; ``contacts`` (T, 2) bool.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.limits import read_npz
from song.datasets.run.layout import AMASS_FILE, MOTION_FILE, MOTION_META_FILE
from song.errors import FormatError
from song.geometry.fk import forward_kinematics
from song.geometry.rotations import vector_norm
from song.pipeline.motion.amass import to_amass, write_amass
from song.pipeline.motion.types import Motion
from song.util import write_json_atomic, write_npz_atomic

MOTION_FORMAT = "song.motion"
MOTION_VERSION = 1
_KEYS = ("t", "frame", "height_m", "rest_joints", "local_quats", "root_pos", "joints", "contacts")


def motion_arrays(motion: Motion) -> dict[str, np.ndarray]:
    """The ``motion.npz`` arrays; joints are FK of the *stored* float32 rotations and root."""
    quats = motion.local_quats / vector_norm(motion.local_quats, keepdims=True)
    quats32 = quats.astype(np.float32)
    root32 = motion.root_pos.astype(np.float32)
    rest32 = motion.rest_joints.astype(np.float32)
    joints = forward_kinematics(rest32.astype(np.float64), quats32.astype(np.float64), root32.astype(np.float64))[0]
    contacts = motion.contacts if motion.contacts is not None else np.zeros((motion.n_frames, 2), dtype=bool)
    return {
        "t": np.asarray(motion.t, dtype=np.float64),
        "frame": np.asarray(motion.frame, dtype=np.int32),
        "height_m": np.array(float(motion.height_m)),
        "rest_joints": rest32,
        "local_quats": quats32,
        "root_pos": root32,
        "joints": joints.astype(np.float32),
        "contacts": np.asarray(contacts, dtype=bool),
    }


def write_motion(traj_dir: str | Path, motion: Motion, meta: dict[str, Any], fps: float) -> list[Path]:
    """Write the three files of one pedestrian; returns their paths."""
    traj_dir = Path(traj_dir)
    traj_dir.mkdir(parents=True, exist_ok=True)
    arrays = motion_arrays(motion)
    write_npz_atomic(traj_dir / MOTION_FILE, **arrays)
    amass = to_amass(arrays["local_quats"], arrays["root_pos"], fps)
    write_amass(traj_dir / AMASS_FILE, amass)
    write_json_atomic(traj_dir / MOTION_META_FILE, meta)
    return [traj_dir / MOTION_FILE, traj_dir / AMASS_FILE, traj_dir / MOTION_META_FILE]


@dataclass(frozen=True)
class LoadedMotion:
    """A motion read back from disk: the ``motion.npz`` arrays and ``meta.json``."""

    t: np.ndarray
    frame: np.ndarray
    height_m: float
    rest_joints: np.ndarray
    local_quats: np.ndarray
    root_pos: np.ndarray
    joints: np.ndarray
    contacts: np.ndarray
    meta: dict[str, Any]


def load_motion(traj_dir: str | Path) -> LoadedMotion:
    """Read ``motion.npz`` and ``meta.json`` of one pedestrian folder (``human_amass/traj_{id}``).

    Raises:
        FormatError: a file is missing, unreadable or lacks a documented array.
    """
    traj_dir = Path(traj_dir)
    path = traj_dir / MOTION_FILE
    arrays = read_npz(path)
    missing = [key for key in _KEYS if key not in arrays]
    if missing:
        raise FormatError(path, missing[0], "missing array (see docs/contracts.md)")
    n = len(arrays["t"])
    if arrays["local_quats"].shape != (n, 24, 4) or arrays["root_pos"].shape != (n, 3):
        raise FormatError(path, "local_quats", f"expected ({n}, 24, 4), got {arrays['local_quats'].shape}")
    try:
        meta = json.loads((traj_dir / MOTION_META_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise FormatError(traj_dir / MOTION_META_FILE, "", f"cannot read ({exc})") from None
    return LoadedMotion(
        t=arrays["t"],
        frame=arrays["frame"],
        height_m=float(arrays["height_m"]),
        rest_joints=arrays["rest_joints"],
        local_quats=arrays["local_quats"],
        root_pos=arrays["root_pos"],
        joints=arrays["joints"],
        contacts=arrays["contacts"],
        meta=meta,
    )
