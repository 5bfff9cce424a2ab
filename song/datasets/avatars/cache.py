"""Animated-avatar caches: the compact default and the paper's materialised form.

**Compact** ``binding/traj_{id}.npz`` (``song.lbs_cache/1``, deflated npz) — kilobytes per pedestrian;
LBS runs at query time:

- ``root_pos (F, 3) float32``: world pelvis per frame (frame ``frame0 + i``, t = frame / fps);
- ``quat_delta (24, 4, F) int16``: parent-local joint rotations (wxyz, relative to the rest pose, the
  root's including the world heading) quantised as ``round(q · 32767)``, sign-continuous in time, stored
  joint/component-major and delta-coded along time with int16 wrap-around (decode: cumulative sum in
  int16, exact), which deflate shrinks about 3×; decoding renormalises (error ≤ 3e-5 rad per joint);
- ``rest_joints (24, 3) float32``: the motion's rest skeleton, which the scaled avatar is bound to;
- ``meta_json``: format, ped_id, avatar_id, avatar_sha256, height_m, scale (avatar → motion height),
  alignment (4×4 avatar canonical → motion rest frame), fps, frame0, n_frames.

**Materialised** ``binding/traj_{id}.materialized.npz`` (``song.lbs_materialized/1``, written on request):
per frame FP16 Gaussian means relative to that frame's root ``positions (F, G, 3)`` and FP16
rotations ``rotations (F, G, 4)``, ``root_pos (F, 3) float32``, the static attributes once
(``log_scales``, ``opacity_logits``, ``sh_dc`` float32, already scaled) and the same metadata.

Both pose identically within FP16 tolerance at frame times (tests). Between frames the compact form
slerps joint rotations; the materialised form interpolates linearly.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.avatars.asset import AvatarAsset
from song.datasets.limits import read_npz
from song.datasets.scenes.ply import GaussianCloud
from song.errors import FormatError
from song.geometry.fk import skinning_transforms
from song.geometry.lbs import SkinnedGaussians, accelerator, lbs, lbs_positions, lbs_rotations
from song.geometry.rotations import quat_continuous, quat_normalize, quat_slerp
from song.util import write_npz_atomic, write_npz_compressed_atomic

COMPACT_FORMAT = "song.lbs_cache/1"
MATERIALIZED_FORMAT = "song.lbs_materialized/1"
QUAT_SCALE = 32767.0


def _meta_array(meta: dict[str, Any]) -> np.ndarray:
    return np.frombuffer(json.dumps(meta, sort_keys=True).encode("utf-8"), dtype=np.uint8)


def _read(path: Path, expected_format: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    try:
        arrays = read_npz(path)
        meta = json.loads(arrays.pop("meta_json").tobytes().decode("utf-8"))
    except (OSError, ValueError, KeyError, UnicodeDecodeError, AttributeError) as exc:
        raise FormatError(path, "", f"cannot read avatar cache ({exc})") from None
    if meta.get("format") != expected_format:
        raise FormatError(path, "meta_json.format", f"expected {expected_format!r}, got {meta.get('format')!r}")
    return arrays, meta


def frame_blend(t: float, fps: float, frame0: int, n_frames: int) -> tuple[int, int, float]:
    """Frames ``i``, ``j = i + 1`` and blend ``a`` in [0, 1) around time ``t`` (clamped to the cached span)."""
    x = float(np.clip(t * fps - frame0, 0.0, n_frames - 1))
    i = min(int(np.floor(x)), n_frames - 1)
    return i, min(i + 1, n_frames - 1), x - i


def encode_rotations(local_quats: np.ndarray) -> np.ndarray:
    """(F, 24, 4) unit quaternions → (24, 4, F) int16 quantised, sign-continuous, delta-coded in time."""
    q = quat_continuous(np.asarray(local_quats, np.float64), axis=0)
    quantised = np.round(np.clip(q, -1.0, 1.0) * QUAT_SCALE).astype(np.int16).transpose(1, 2, 0)
    return np.diff(quantised, axis=-1, prepend=np.zeros_like(quantised[..., :1]))  # int16, wraps exactly


def decode_rotations(delta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`encode_rotations`: (F, 24, 4) float32 unit quaternions."""
    quantised = np.cumsum(delta, axis=-1, dtype=np.int16)
    return quat_normalize(quantised.transpose(2, 0, 1).astype(np.float32) / np.float32(QUAT_SCALE))


@dataclass(frozen=True)
class MotionCache:
    """A compact cache decoded: the motion an avatar is posed with.

    Attributes:
        root_pos: (F, 3) float32 world pelvis positions, m.
        local_quats: (F, 24, 4) float32 parent-local rotations.
        rest_joints: (24, 3) float32 rest skeleton, m.
        fps: frames per second; frame ``frame0 + i`` is at ``t = (frame0 + i) / fps``.
        frame0: first frame index.
        meta: the cache metadata.
    """

    root_pos: np.ndarray
    local_quats: np.ndarray
    rest_joints: np.ndarray
    fps: float
    frame0: int
    meta: dict[str, Any]

    def __len__(self) -> int:
        return len(self.root_pos)

    def transforms(self, frames: np.ndarray | slice | None = None) -> np.ndarray:
        """(F, 24, 3, 4) float32 skinning transforms of the cached frames (all by default)."""
        index = slice(None) if frames is None else frames
        return skinning_transforms(self.rest_joints, self.local_quats[index], self.root_pos[index]).astype(np.float32)

    def transforms_at(self, t: float) -> np.ndarray:
        """(24, 3, 4) float32 transforms at time ``t``: joint rotations slerped, root lerped between frames."""
        i, j, a = frame_blend(t, self.fps, self.frame0, len(self))
        quats = quat_slerp(self.local_quats[i], self.local_quats[j], a)
        root = (1 - a) * self.root_pos[i].astype(np.float64) + a * self.root_pos[j]
        return skinning_transforms(self.rest_joints.astype(np.float64), quats, root).astype(np.float32)


def write_compact_cache(
    path: str | Path, root_pos: np.ndarray, local_quats: np.ndarray, rest_joints: np.ndarray, meta: dict[str, Any]
) -> None:
    """Write a compact cache (see the module docstring); ``meta`` must carry fps and frame0."""
    meta = {**meta, "format": COMPACT_FORMAT, "n_frames": len(root_pos)}
    write_npz_compressed_atomic(
        path,
        root_pos=np.asarray(root_pos, np.float32),
        quat_delta=encode_rotations(local_quats),
        rest_joints=np.asarray(rest_joints, np.float32),
        meta_json=_meta_array(meta),
    )


def load_compact_cache(path: str | Path) -> MotionCache:
    """Read a compact cache. Raises :class:`FormatError` naming the file and field."""
    path = Path(path)
    arrays, meta = _read(path, COMPACT_FORMAT)
    for key in ("root_pos", "quat_delta", "rest_joints"):
        if key not in arrays:
            raise FormatError(path, key, "missing array")
    n = len(arrays["root_pos"])
    if arrays["quat_delta"].shape != (24, 4, n) or arrays["quat_delta"].dtype != np.int16:
        raise FormatError(path, "quat_delta", f"expected int16 (24, 4, {n}), got {arrays['quat_delta'].shape}")
    return MotionCache(
        arrays["root_pos"],
        decode_rotations(arrays["quat_delta"]),
        arrays["rest_joints"],
        float(meta["fps"]),
        int(meta["frame0"]),
        meta,
    )


def skin_asset(asset: AvatarAsset) -> SkinnedGaussians:
    """The asset's canonical Gaussians prepared for :mod:`song.geometry.lbs`."""
    cloud = asset.gaussians
    return SkinnedGaussians.build(cloud.means, cloud.quats, asset.skin_indices, asset.skin_weights)


def write_materialized_cache(path: str | Path, asset: AvatarAsset, motion: MotionCache, chunk: int = 256) -> None:
    """Pose every frame and write the paper's FP16 form (``asset`` already scaled to the motion)."""
    skin = skin_asset(asset)
    device = accelerator()
    if device is not None:  # bulk posing on the GPU when there is one (same code path, torch tensors)
        import torch

        skin = skin.to_torch(device)
    n, g = len(motion), len(asset)
    positions = np.empty((n, g, 3), np.float16)
    rotations = np.empty((n, g, 4), np.float16)
    for start in range(0, n, chunk):
        frames = slice(start, min(start + chunk, n))
        transforms = motion.transforms(frames)
        if device is not None:
            posed, quats = (x.cpu().numpy() for x in lbs(skin, torch.as_tensor(transforms, device=device)))
        else:
            posed, quats = lbs(skin, transforms)
        positions[frames] = posed - motion.root_pos[frames, None, :]
        rotations[frames] = quats
    cloud = asset.gaussians
    meta = {**motion.meta, "format": MATERIALIZED_FORMAT, "n_gaussians": g}
    write_npz_atomic(
        path,
        positions=positions,
        rotations=rotations,
        root_pos=motion.root_pos.astype(np.float32),
        log_scales=cloud.log_scales.astype(np.float32),
        opacity_logits=cloud.opacity_logits.astype(np.float32),
        sh_dc=cloud.sh_dc.astype(np.float32),
        meta_json=_meta_array(meta),
    )


@dataclass(frozen=True)
class MaterializedCache:
    """The paper's form read back: FP16 per-frame means relative to the root, FP16 rotations."""

    positions: np.ndarray
    rotations: np.ndarray
    root_pos: np.ndarray
    fps: float
    frame0: int
    meta: dict[str, Any]

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """World means (G, 3) float32 and unit rotations (G, 4) at ``t`` (linear between frames)."""
        i, j, a = frame_blend(t, self.fps, self.frame0, len(self.root_pos))
        a = np.float32(a)
        means = (1 - a) * (self.positions[i] + self.root_pos[i]) + a * (self.positions[j] + self.root_pos[j])
        quats = self.rotations[i].astype(np.float32)
        other = self.rotations[j].astype(np.float32)
        other = np.where((quats * other).sum(-1, keepdims=True) < 0, -other, other)
        return means.astype(np.float32), quat_normalize((1 - a) * quats + a * other).astype(np.float32)


def load_materialized_cache(path: str | Path) -> MaterializedCache:
    """Read a materialised cache. Raises :class:`FormatError` naming the file and field."""
    path = Path(path)
    arrays, meta = _read(path, MATERIALIZED_FORMAT)
    for key in ("positions", "rotations", "root_pos"):
        if key not in arrays:
            raise FormatError(path, key, "missing array")
    return MaterializedCache(
        arrays["positions"], arrays["rotations"], arrays["root_pos"], float(meta["fps"]), int(meta["frame0"]), meta
    )


@dataclass(frozen=True)
class PosedAvatar:
    """One pedestrian's avatar ready to pose: prepared Gaussians plus its motion cache.

    Attributes:
        skin: the scaled canonical Gaussians prepared for LBS.
        motion: the decoded compact cache.
        gaussians: the scaled canonical Gaussians (their scales, opacities and colours are static).
    """

    skin: SkinnedGaussians
    motion: MotionCache
    gaussians: GaussianCloud

    @classmethod
    def load(cls, asset: AvatarAsset, cache: MotionCache) -> PosedAvatar:
        """Scale the asset as recorded in the cache and prepare it."""
        scaled = asset.scaled(float(cache.meta.get("scale", 1.0)))
        return cls(skin_asset(scaled), cache, scaled.gaussians)

    def means_at(self, t: float) -> np.ndarray:
        """(G, 3) float32 posed Gaussian means at scenario time ``t`` (s)."""
        return lbs_positions(self.skin, self.motion.transforms_at(t))

    def pose_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Posed means (G, 3) and rotations (G, 4, wxyz) at scenario time ``t`` (s), by LBS."""
        transforms = self.motion.transforms_at(t)
        return lbs_positions(self.skin, transforms), lbs_rotations(self.skin, transforms)


def pose_avatars(avatars: list[PosedAvatar], t: float) -> list[np.ndarray]:
    """Posed means of several avatars at one time ``t``: a list of (G_i, 3) float32 arrays."""
    return [avatar.means_at(t) for avatar in avatars]
