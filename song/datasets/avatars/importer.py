"""Import a real Gaussian avatar (standard 3DGS PLY in a canonical T- or A-pose, e.g. an LHM export).

Steps: detect the up and forward axes (or take them from the caller), rotate into SONG's body frame
(x forward, y left, z up), put the feet on z = 0 and the hips over the origin, scale to the requested
height, bind to our rest skeleton of that height (:func:`transfer_weights`), validate, return the asset.

Axis detection, for a person standing in a canonical pose:

- **up** is one of the two longest axes of the bounding box (in a T-pose the arm span rivals the height);
  of those, the axis along which the body is *not* concentrated in the middle (the lateral axis has
  the torso at its centre and only thin arms outside the central 30 %);
- **its sign**: the top slice (head) is narrower across than the bottom slice (two feet apart);
- **forward** is the remaining axis; **its sign**: toes point forward, so the lowest slice's centroid
  lies ahead of the shins' centroid.

Each rule is checked for a clear margin; an ambiguous body raises a one-line error asking for
``up``/``forward`` explicitly.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from song.datasets.avatars.asset import AvatarAsset, validate_avatar
from song.datasets.avatars.skinning import transfer_weights
from song.datasets.scenes.ply import read_gaussian_ply
from song.errors import FormatError
from song.geometry.rotations import matrix_to_quat, quat_mul, quat_normalize
from song.geometry.skeleton import rest_joints

AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}


def _unit(spec: str, path: Path, name: str) -> np.ndarray:
    if spec not in AXES:
        raise FormatError(path, name, f"{spec!r} is not one of {sorted(AXES)}")
    axis, sign = AXES[spec]
    out = np.zeros(3)
    out[axis] = sign
    return out


def _slice(points: np.ndarray, along: np.ndarray, lo: float, hi: float) -> np.ndarray:
    h = points @ along
    h0, span = h.min(), np.ptp(h)
    return points[(h >= h0 + lo * span) & (h <= h0 + hi * span)]


def detect_up(points: np.ndarray, path: Path) -> np.ndarray:
    """Unit up vector along a coordinate axis (see the module docstring)."""
    extent = np.ptp(points, axis=0)
    candidates = np.argsort(-extent)[:2]
    central = []
    for axis in candidates:
        x = points[:, axis]
        mid, half = (x.min() + x.max()) / 2, 0.15 * np.ptp(x)
        central.append(np.mean(np.abs(x - mid) <= half))
    up_axis = int(candidates[int(np.argmin(central))])
    if abs(central[0] - central[1]) < 0.1:
        raise FormatError(path, "up", "cannot tell up from the arm span; pass up explicitly (e.g. '+y')")
    up = np.zeros(3)
    up[up_axis] = 1.0
    lateral = int(candidates[int(np.argmax(central))])
    top = np.ptp(_slice(points, up, 0.9, 1.0)[:, lateral])
    bottom = np.ptp(_slice(points, up, 0.0, 0.1)[:, lateral])
    if abs(top - bottom) < 0.1 * max(top, bottom):
        raise FormatError(path, "up", "cannot tell head from feet; pass up explicitly")
    return up if top < bottom else -up


def detect_forward(points: np.ndarray, up: np.ndarray, path: Path) -> np.ndarray:
    """Unit forward vector along the remaining depth axis (toes point forward)."""
    extent = np.ptp(points, axis=0)
    free = [a for a in range(3) if abs(up[a]) < 0.5]
    depth = min(free, key=lambda a: extent[a])
    feet = _slice(points, up, 0.0, 0.04)[:, depth].mean()
    shins = _slice(points, up, 0.1, 0.25)[:, depth].mean()
    if abs(feet - shins) < 0.01 * np.ptp(points @ up):
        raise FormatError(path, "forward", "cannot tell front from back; pass forward explicitly (e.g. '+z')")
    forward = np.zeros(3)
    forward[depth] = 1.0 if feet > shins else -1.0
    return forward


def canonical_frame(points: np.ndarray, path: Path, up: str | None, forward: str | None) -> np.ndarray:
    """Rotation (3, 3) taking source coordinates to the body frame (rows: forward, left, up)."""
    up_vec = _unit(up, path, "up") if up else detect_up(points, path)
    fwd_vec = _unit(forward, path, "forward") if forward else detect_forward(points, up_vec, path)
    if abs(float(up_vec @ fwd_vec)) > 1e-6:
        raise FormatError(path, "forward", "forward must be perpendicular to up")
    return np.stack([fwd_vec, np.cross(up_vec, fwd_vec), up_vec])


def import_ply_avatar(
    path: str | Path,
    avatar_id: str,
    height_m: float = 1.75,
    up: str | None = None,
    forward: str | None = None,
    source: str = "",
) -> AvatarAsset:
    """Read a standard 3DGS PLY avatar and return it in SONG's asset format.

    Args:
        path: the PLY (standard or SuperSplat compressed).
        avatar_id: id of the new identity.
        height_m: body height to scale to, metres.
        up: the source's up axis such as ``"+y"`` (detected when omitted).
        forward: the source's forward axis such as ``"+z"`` (detected when omitted).
        source: provenance text stored in the metadata.

    Raises:
        FormatError: unreadable PLY, or axes that cannot be detected unambiguously.
    """
    path = Path(path)
    cloud = read_gaussian_ply(path)
    points = cloud.means.astype(np.float64)
    rotation = canonical_frame(points, path, up, forward)
    body = points @ rotation.T
    scale = height_m / float(np.ptp(body[:, 2]))
    hips = _slice(body, np.array([0.0, 0.0, 1.0]), 0.45, 0.55)[:, :2].mean(axis=0)
    offset = -np.array([hips[0], hips[1], body[:, 2].min()])
    means = (body + offset) * scale
    alignment = np.eye(4)
    alignment[:3, :3] = scale * rotation
    alignment[:3, 3] = scale * offset
    turn = matrix_to_quat(rotation)
    quats = quat_normalize(quat_mul(np.broadcast_to(turn, cloud.quats.shape), cloud.quats.astype(np.float64)))
    canonical = replace(
        cloud,
        means=means.astype(np.float32),
        quats=quats.astype(np.float32),
        log_scales=(cloud.log_scales + np.float32(np.log(scale))).astype(np.float32),
    )
    rest = rest_joints(height_m)
    indices, weights = transfer_weights(means, rest, height_m)
    meta = {
        "source": source or f"imported:{path.name}",
        "height_m": float(height_m),
        "scale": 1.0,
        "alignment": alignment.ravel().tolist(),
        "generator": {"importer": "song.datasets.avatars.importer", "up": up or "auto", "forward": forward or "auto"},
    }
    asset = AvatarAsset(avatar_id, canonical, indices, weights, rest.astype(np.float32), meta)
    validate_avatar(asset, path)
    return asset
