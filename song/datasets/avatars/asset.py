"""Avatar asset format: one identity per file, canonical Gaussians plus skinning.

An asset file ``<avatar_id>.avatar.npz`` (uncompressed npz, no pickles) holds:

- ``means (G, 3) float32`` m, ``quats (G, 4) float32`` unit wxyz, ``log_scales (G, 3) float32``,
  ``opacity_logits (G,) float32``, ``sh_dc (G, 3) float32`` and optionally ``sh_rest (G, K, 3)``:
  the Gaussians in the **rest pose** (T-pose), body frame x forward, y left, z up, feet on z = 0;
- ``skin_indices (G, 4) uint8`` joint indices into the 24-joint skeleton and ``skin_weights (G, 4)
  float32`` (descending, summing to 1): the top-4 linear-blend-skinning weights;
- ``rest_joints (24, 3) float32`` the rest skeleton the Gaussians are bound to (metres);
- ``meta_json (B,) uint8``: UTF-8 JSON ``{format, avatar_id, source, height_m, scale, alignment
  (4×4 row-major, source frame → canonical), generator {…}, n_gaussians, sha256}``.

``sha256`` is the hash of the content (every array's dtype, shape and bytes, then the canonical JSON
of the metadata without ``sha256``); :func:`load_avatar` recomputes it, so a corrupted or edited file
is refused. :func:`export_avatar_ply` writes the same identity as a standard 3DGS PLY (any splat viewer
opens it) plus a ``.skin.npz`` sidecar with the skinning arrays and metadata; :func:`import_avatar_ply`
reads the pair back.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.limits import read_npz
from song.datasets.scenes.ply import GaussianCloud, read_gaussian_ply, write_standard_ply
from song.errors import FormatError
from song.geometry.skeleton import N_JOINTS
from song.util import canonical_json, check_id, write_npz_atomic, write_npz_compressed_atomic

FORMAT = "song.avatar/1"
SUFFIX = ".avatar.npz"
SIDECAR_SUFFIX = ".skin.npz"
TOP_K = 4
_CLOUD_KEYS = ("means", "quats", "log_scales", "opacity_logits", "sh_dc")


@dataclass
class AvatarAsset:
    """One avatar identity.

    Attributes:
        avatar_id: identity id (file stem).
        gaussians: canonical Gaussians in the rest pose (see the module docstring for the frame).
        skin_indices: (G, 4) uint8 joint indices.
        skin_weights: (G, 4) float32 weights, rows sum to 1.
        rest_joints: (24, 3) float32 rest skeleton, metres.
        meta: metadata (source, height_m, scale, alignment, generator parameters).
    """

    avatar_id: str
    gaussians: GaussianCloud
    skin_indices: np.ndarray
    skin_weights: np.ndarray
    rest_joints: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def height_m(self) -> float:
        """Body height of the rest pose, m."""
        return float(self.meta["height_m"])

    def __len__(self) -> int:
        return len(self.gaussians)

    def scaled(self, factor: float) -> AvatarAsset:
        """The same identity uniformly scaled about the origin (feet stay on z = 0); log-scales shift."""
        cloud = replace(
            self.gaussians,
            means=(self.gaussians.means * factor).astype(np.float32),
            log_scales=(self.gaussians.log_scales + np.float32(np.log(factor))).astype(np.float32),
        )
        meta = {**self.meta, "height_m": self.height_m * factor, "scale": float(self.meta.get("scale", 1.0)) * factor}
        meta.pop("sha256", None)
        rest = (self.rest_joints * factor).astype(np.float32)
        return AvatarAsset(self.avatar_id, cloud, self.skin_indices, self.skin_weights, rest, meta)


def asset_arrays(asset: AvatarAsset) -> dict[str, np.ndarray]:
    """The asset's arrays in file order (without ``meta_json``)."""
    cloud = asset.gaussians
    arrays = {
        "means": np.ascontiguousarray(cloud.means, np.float32),
        "quats": np.ascontiguousarray(cloud.quats, np.float32),
        "log_scales": np.ascontiguousarray(cloud.log_scales, np.float32),
        "opacity_logits": np.ascontiguousarray(cloud.opacity_logits, np.float32),
        "sh_dc": np.ascontiguousarray(cloud.sh_dc, np.float32),
    }
    if cloud.sh_rest is not None:
        arrays["sh_rest"] = np.ascontiguousarray(cloud.sh_rest, np.float32)
    arrays["skin_indices"] = np.ascontiguousarray(asset.skin_indices, np.uint8)
    arrays["skin_weights"] = np.ascontiguousarray(asset.skin_weights, np.float32)
    arrays["rest_joints"] = np.ascontiguousarray(asset.rest_joints, np.float32)
    return arrays


def content_sha256(arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> str:
    """Hash of the arrays (name, dtype, shape, bytes in key order) and the metadata without ``sha256``."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    digest.update(canonical_json({k: v for k, v in meta.items() if k != "sha256"}).encode("utf-8"))
    return digest.hexdigest()


def _full_meta(asset: AvatarAsset, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    meta = {k: v for k, v in asset.meta.items() if k != "sha256"}
    meta.update(format=FORMAT, avatar_id=asset.avatar_id, n_gaussians=len(asset))
    meta.setdefault("scale", 1.0)
    meta.setdefault("alignment", np.eye(4).ravel().tolist())
    meta["sha256"] = content_sha256(arrays, meta)
    return meta


def _meta_bytes(meta: dict[str, Any]) -> np.ndarray:
    return np.frombuffer(json.dumps(meta, sort_keys=True).encode("utf-8"), dtype=np.uint8)


def save_avatar(asset: AvatarAsset, folder: str | Path) -> Path:
    """Validate and write ``folder/<avatar_id>.avatar.npz`` atomically; returns the path.

    Raises:
        FormatError: the asset breaks the format (see :func:`validate_avatar`).
    """
    path = Path(folder) / f"{check_id(asset.avatar_id, 'avatar id')}{SUFFIX}"
    validate_avatar(asset, path)
    arrays = asset_arrays(asset)
    meta = _full_meta(asset, arrays)
    asset.meta = meta
    Path(folder).mkdir(parents=True, exist_ok=True)
    write_npz_compressed_atomic(path, **arrays, meta_json=_meta_bytes(meta))  # deflated: 1.8 MB, not 3.0
    return path


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    return read_npz(path)


def _parse_meta(arrays: dict[str, np.ndarray], path: Path) -> dict[str, Any]:
    if "meta_json" not in arrays:
        raise FormatError(path, "meta_json", "missing array")
    try:
        meta = json.loads(arrays.pop("meta_json").tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise FormatError(path, "meta_json", f"not UTF-8 JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise FormatError(path, "meta_json.format", f"expected {FORMAT!r}")
    for key in ("avatar_id", "height_m"):
        if key not in meta:
            raise FormatError(path, f"meta_json.{key}", "missing")
    return meta


def _asset_from_arrays(arrays: dict[str, np.ndarray], meta: dict[str, Any], path: Path) -> AvatarAsset:
    missing = [key for key in (*_CLOUD_KEYS, "skin_indices", "skin_weights", "rest_joints") if key not in arrays]
    if missing:
        raise FormatError(path, missing[0], "missing array (see docs/avatars.md)")
    cloud = GaussianCloud(*(arrays[key] for key in _CLOUD_KEYS), sh_rest=arrays.get("sh_rest"))
    asset = AvatarAsset(
        str(meta["avatar_id"]), cloud, arrays["skin_indices"], arrays["skin_weights"], arrays["rest_joints"], meta
    )
    validate_avatar(asset, path)
    return asset


def load_avatar(path: str | Path) -> AvatarAsset:
    """Read an asset file and check its format and content hash.

    Raises:
        FormatError: unreadable file, missing or malformed array, or a content hash mismatch.
    """
    path = Path(path)
    arrays = _read_npz(path)
    meta = _parse_meta(arrays, path)
    asset = _asset_from_arrays(arrays, meta, path)
    if meta.get("sha256") != content_sha256(asset_arrays(asset), meta):
        raise FormatError(path, "meta_json.sha256", "content hash mismatch (file altered or corrupted)")
    return asset


def validate_avatar(asset: AvatarAsset, path: str | Path) -> None:
    """Check shapes, dtypes ranges and skinning invariants; raise a one-line :class:`FormatError`."""
    cloud, g = asset.gaussians, len(asset)
    shapes = {
        "means": (cloud.means, (g, 3)),
        "quats": (cloud.quats, (g, 4)),
        "log_scales": (cloud.log_scales, (g, 3)),
        "opacity_logits": (cloud.opacity_logits, (g,)),
        "sh_dc": (cloud.sh_dc, (g, 3)),
        "skin_indices": (asset.skin_indices, (g, TOP_K)),
        "skin_weights": (asset.skin_weights, (g, TOP_K)),
        "rest_joints": (asset.rest_joints, (N_JOINTS, 3)),
    }
    for name, (array, shape) in shapes.items():
        if np.shape(array) != shape:
            raise FormatError(path, name, f"expected shape {shape}, got {np.shape(array)}")
        if name != "skin_indices" and not np.isfinite(array).all():
            raise FormatError(path, name, "non-finite values")
    if g == 0:
        raise FormatError(path, "means", "no Gaussians")
    if np.abs(np.linalg.norm(cloud.quats, axis=1) - 1.0).max() > 1e-3:
        raise FormatError(path, "quats", "not unit quaternions")
    if int(np.max(asset.skin_indices)) >= N_JOINTS:
        raise FormatError(path, "skin_indices", f"joint index ≥ {N_JOINTS}")
    weights = np.asarray(asset.skin_weights)
    if (weights < 0).any() or np.abs(weights.sum(axis=1) - 1.0).max() > 1e-4:
        raise FormatError(path, "skin_weights", "weights must be ≥ 0 and sum to 1 per Gaussian")
    height = float(asset.meta.get("height_m", 0.0))
    if not 0.3 <= height <= 3.0:
        raise FormatError(path, "meta_json.height_m", f"{height} m is not a plausible body height")


def export_avatar_ply(asset: AvatarAsset, folder: str | Path) -> tuple[Path, Path]:
    """Write ``<id>.ply`` (standard 3DGS, rest pose) and ``<id>.skin.npz`` (skinning sidecar)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    arrays = asset_arrays(asset)
    meta = _full_meta(asset, arrays)
    ply = folder / f"{asset.avatar_id}.ply"
    sidecar = folder / f"{asset.avatar_id}{SIDECAR_SUFFIX}"
    write_standard_ply(ply, asset.gaussians)
    skin = {key: arrays[key] for key in ("skin_indices", "skin_weights", "rest_joints")}
    write_npz_atomic(sidecar, **skin, meta_json=_meta_bytes(meta))
    return ply, sidecar


def import_avatar_ply(ply: str | Path, sidecar: str | Path | None = None) -> AvatarAsset:
    """Read an avatar exported by :func:`export_avatar_ply` (PLY + ``.skin.npz`` beside it by default)."""
    ply = Path(ply)
    sidecar = Path(sidecar) if sidecar else ply.with_name(ply.name.removesuffix(".ply") + SIDECAR_SUFFIX)
    cloud = read_gaussian_ply(ply)
    arrays = _read_npz(sidecar)
    meta = _parse_meta(arrays, sidecar)
    arrays.update({key: getattr(cloud, key) for key in _CLOUD_KEYS})
    if cloud.sh_rest is not None:
        arrays["sh_rest"] = cloud.sh_rest
    return _asset_from_arrays(arrays, meta, ply)


def list_avatars(folder: str | Path) -> list[Path]:
    """Asset files of a pool folder, sorted by name."""
    return sorted(Path(folder).glob(f"*{SUFFIX}"))
