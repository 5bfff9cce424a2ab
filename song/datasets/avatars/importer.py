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

Plausibility (:func:`human_shape_problems`): once upright and scaled, a standing person is broad at the
hips and shoulders for their height (hip and shoulder breadth are about 20 % and 24 % of stature in
adults), has a head clearly narrower than the shoulders, and is shallower front to back than across.
A splat failing any of these (a guitar scaled to 1.75 m is 9 cm wide at the "hips") is refused unless
the caller passes the axes explicitly and ``force``.
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

MIN_SPLATS = 100  # fewer Gaussians cannot cover the 24 skinned body parts of a person
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


MIN_HIP_WIDTH, MIN_SHOULDER_WIDTH = 0.12, 0.17  # × height: well below any adult's or child's (≈ 0.20, 0.24)
MAX_HEAD_TO_SHOULDERS, MAX_DEPTH_TO_WIDTH = 0.75, 1.25


def _width(means: np.ndarray, height: float, lo: float, hi: float, axis: int = 1) -> float:
    """Robust extent (2nd–98th percentile, m) along ``axis`` of the slice lo…hi × height."""
    z = means[:, 2]
    part = means[(z >= lo * height) & (z <= hi * height), axis]
    return float(np.percentile(part, 98) - np.percentile(part, 2)) if len(part) > 20 else 0.0


def human_shape_problems(means: np.ndarray, height: float) -> list[str]:
    """Why upright, scaled Gaussian means (body frame, feet at z = 0) do not look like a standing person."""
    hips, shoulders = _width(means, height, 0.45, 0.55), _width(means, height, 0.72, 0.82)
    head = _width(means, height, 0.9, 1.0)
    chest_w, chest_d = _width(means, height, 0.6, 0.72), _width(means, height, 0.6, 0.72, axis=0)
    problems = []
    if hips < MIN_HIP_WIDTH * height:
        problems.append(f"hip width {hips:.2f} m (a person of {height:g} m: ≥ {MIN_HIP_WIDTH * height:.2f} m)")
    if shoulders < MIN_SHOULDER_WIDTH * height:
        problems.append(f"shoulder width {shoulders:.2f} m (≥ {MIN_SHOULDER_WIDTH * height:.2f} m)")
    if head > MAX_HEAD_TO_SHOULDERS * max(shoulders, 1e-9):
        problems.append(f"head {head:.2f} m wide, not narrower than the shoulders ({shoulders:.2f} m)")
    if chest_d > MAX_DEPTH_TO_WIDTH * max(chest_w, 1e-9):
        problems.append(f"deeper ({chest_d:.2f} m) than wide ({chest_w:.2f} m) at the chest")
    return problems


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
    force: bool = False,
) -> AvatarAsset:
    """Read a standard 3DGS PLY avatar and return it in SONG's asset format.

    Args:
        path: the PLY (standard or SuperSplat compressed).
        avatar_id: id of the new identity.
        height_m: body height to scale to, metres.
        up: the source's up axis such as ``"+y"`` (detected when omitted).
        forward: the source's forward axis such as ``"+z"`` (detected when omitted).
        source: provenance text stored in the metadata.
        force: import even a splat that does not look like a standing person (needs ``up`` and
            ``forward``: detection assumes a person).

    Raises:
        FormatError: unreadable PLY, axes that cannot be detected unambiguously, or a splat that
            does not look like a person (without ``force``).
    """
    path = Path(path)
    cloud = read_gaussian_ply(path)
    points = cloud.means.astype(np.float64)
    if len(points) < MIN_SPLATS:
        raise FormatError(path, "vertex", f"{len(points)} splats; an avatar needs at least {MIN_SPLATS}")
    rotation = canonical_frame(points, path, up, forward)
    body = points @ rotation.T
    extent = float(np.ptp(body[:, 2]))
    if not extent > 0:
        raise FormatError(path, "vertex", "the splats have no extent along the up axis")
    scale = height_m / extent
    at_hips = _slice(body, np.array([0.0, 0.0, 1.0]), 0.45, 0.55)
    if not len(at_hips):
        raise FormatError(path, "vertex", "no splats at hip height (45-55 % of the body's height)")
    hips = at_hips[:, :2].mean(axis=0)
    offset = -np.array([hips[0], hips[1], body[:, 2].min()])
    means = (body + offset) * scale
    problems = human_shape_problems(means, height_m)
    if problems and not force:
        raise FormatError(
            path,
            "shape",
            "does not look like a standing person: "
            + "; ".join(problems)
            + " (pass --up, --forward and --force to import it anyway)",
        )
    if force and not (up and forward):
        raise FormatError(path, "force", "--force needs the source axes: pass --up and --forward")
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
