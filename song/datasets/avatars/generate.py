"""Procedural Gaussian avatars: a parametric body with clothing, hair and skin tone (DESIGN §5.4).

The body is a set of surfaces around the bones of :func:`song.geometry.skeleton.rest_joints` in the
T-pose — tapered elliptic tubes for the torso and limbs, ellipsoids for the head, hands and feet —
whose radii follow the height and a girth factor. Gaussians are flat discs on those surfaces (the
normal is the thin axis), their number split between parts in proportion to area so the surface is
evenly covered. Clothing and hair colour the discs by region (tops with short or long sleeves,
trousers, shorts, skirts, dresses with a cone from the waist; solid, striped or two-tone; hair caps,
long hair, buns, ponytails) and add the extra surfaces skirts and hair need. Skinning weights come from
:func:`transfer_weights`, except skirts and dresses, which hang from the pelvis and follow the hips
towards the hem.

Every parameter is drawn from the avatar's own generator (``derive_rng(seed, "avatar", index)``), so
avatar ``i`` of a pool does not depend on the pool's size, and the same seed gives identical files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.avatars.asset import AvatarAsset, save_avatar
from song.datasets.avatars.skinning import top_k, transfer_weights
from song.datasets.scenes.ply import SH_C0, GaussianCloud
from song.geometry.rotations import matrix_to_quat
from song.geometry.skeleton import JOINT_INDEX as J
from song.geometry.skeleton import N_JOINTS, rest_joints
from song.util import derive_rng

GENERATOR_VERSION = 1
SKIN_TONES = np.array(  # sRGB 0–1, light to deep (a spread of real skin reflectances)
    [
        [0.96, 0.84, 0.74],
        [0.92, 0.76, 0.62],
        [0.84, 0.64, 0.48],
        [0.72, 0.52, 0.36],
        [0.55, 0.37, 0.24],
        [0.36, 0.23, 0.15],
    ]
)
HAIR_COLOURS = np.array(
    [
        [0.06, 0.05, 0.05],
        [0.20, 0.13, 0.08],
        [0.36, 0.24, 0.14],
        [0.72, 0.58, 0.36],
        [0.55, 0.24, 0.12],
        [0.62, 0.62, 0.6],
    ]
)
TOPS = ("tshirt", "longsleeve", "tank")
BOTTOMS = ("trousers", "shorts", "skirt")
PATTERNS = ("solid", "stripes", "two_tone")
HAIR = ("short", "long", "bun", "ponytail", "bald")


@dataclass
class AvatarParams:
    """What an identity looks like (all lengths in metres, colours sRGB in [0, 1])."""

    height_m: float
    girth: float
    shoulders: float
    hips: float
    skin: list[float]
    top: str
    bottom: str
    dress: bool
    pattern: str
    top_colour: list[float]
    accent_colour: list[float]
    bottom_colour: list[float]
    shoe_colour: list[float]
    hair: str
    hair_colour: list[float]
    stripe_m: float = 0.04
    extra: dict[str, Any] = field(default_factory=dict)


def _colour(rng: np.random.Generator) -> list[float]:
    """A clothing colour: random hue, mostly muted saturation, varied value (HSV → RGB)."""
    h, s, v = rng.random(), rng.choice([rng.uniform(0.05, 0.3), rng.uniform(0.35, 0.85)]), rng.uniform(0.15, 0.95)
    k = (np.array([5.0, 3.0, 1.0]) + h * 6.0) % 6.0
    rgb = v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return [round(float(c), 4) for c in rgb]


def sample_params(rng: np.random.Generator) -> AvatarParams:
    """Draw one identity's parameters."""
    tone = rng.uniform(0, len(SKIN_TONES) - 1)
    low = int(np.floor(tone))
    skin = SKIN_TONES[low] + (tone - low) * (SKIN_TONES[min(low + 1, len(SKIN_TONES) - 1)] - SKIN_TONES[low])
    dress = bool(rng.random() < 0.12)
    return AvatarParams(
        height_m=round(float(rng.uniform(1.55, 1.95)), 4),
        girth=round(float(rng.uniform(0.85, 1.2)), 4),
        shoulders=round(float(rng.uniform(0.9, 1.1)), 4),
        hips=round(float(rng.uniform(0.9, 1.12)), 4),
        skin=[round(float(c), 4) for c in skin],
        top=str(rng.choice(TOPS)),
        bottom="skirt" if dress else str(rng.choice(BOTTOMS, p=[0.6, 0.2, 0.2])),
        dress=dress,
        pattern=str(rng.choice(PATTERNS, p=[0.55, 0.25, 0.2])),
        top_colour=_colour(rng),
        accent_colour=_colour(rng),
        bottom_colour=_colour(rng),
        shoe_colour=_colour(rng),
        hair=str(rng.choice(HAIR, p=[0.35, 0.25, 0.12, 0.13, 0.15])),
        hair_colour=[round(float(c), 4) for c in HAIR_COLOURS[rng.integers(len(HAIR_COLOURS))]],
        stripe_m=round(float(rng.uniform(0.025, 0.06)), 4),
    )


@dataclass
class _Part:
    """A surface: a tapered elliptic tube between two points, or an ellipsoid (``end`` None)."""

    name: str
    start: np.ndarray
    end: np.ndarray | None
    radii: tuple[float, float, float]  # tube: (r0, r1, depth/width ratio); ellipsoid: semi-axes
    region: str


def _body_parts(p: AvatarParams, rest: np.ndarray) -> list[_Part]:
    h, g = p.height_m, p.girth
    s = h / 1.75

    def tube(name, a, b, r0, r1, region, flat=1.0):
        return _Part(
            name,
            rest[J[a]] if isinstance(a, str) else a,
            rest[J[b]] if isinstance(b, str) else b,
            (r0 * s * g, r1 * s * g, flat),
            region,
        )

    pelvis, neck = rest[J["pelvis"]], rest[J["neck"]]
    parts = [
        _Part(
            "head", rest[J["head"]] + np.array([0.012, 0.0, 0.104]) * s, None, (0.1 * s, 0.085 * s, 0.115 * s), "head"
        ),
        tube("neck", "neck", rest[J["head"]] + np.array([0, 0, 0.02 * s]), 0.05, 0.048, "neck"),
        tube(
            "torso",
            pelvis - np.array([0, 0, 0.06 * s]),
            neck - np.array([0, 0, 0.03 * s]),
            0.165 * p.hips,
            0.175 * p.shoulders,
            "torso",
            flat=0.62,
        ),
        tube("shoulders", rest[J["left_shoulder"]] * [1, 1, 1], rest[J["right_shoulder"]], 0.055, 0.055, "torso"),
    ]
    for side in ("left", "right"):
        parts += [
            tube(f"{side}_upper_arm", f"{side}_shoulder", f"{side}_elbow", 0.048, 0.04, f"{side}_upper_arm"),
            tube(f"{side}_forearm", f"{side}_elbow", f"{side}_wrist", 0.039, 0.031, f"{side}_forearm"),
            _Part(
                f"{side}_hand",
                0.5 * (rest[J[f"{side}_wrist"]] + rest[J[f"{side}_hand"]]),
                None,
                (0.022 * s, 0.05 * s, 0.045 * s),
                "hand",
            ),
            tube(f"{side}_thigh", f"{side}_hip", f"{side}_knee", 0.08 * p.hips, 0.056, f"{side}_thigh"),
            tube(f"{side}_shin", f"{side}_knee", f"{side}_ankle", 0.054, 0.038, f"{side}_shin"),
            _Part(
                f"{side}_foot",
                0.5 * (rest[J[f"{side}_ankle"]] + rest[J[f"{side}_foot"]]) + np.array([0.01, 0, -0.01]) * s,
                None,
                (0.12 * s, 0.048 * s, 0.04 * s),
                "foot",
            ),
        ]
    if p.bottom == "skirt":
        waist = pelvis + np.array([0, 0, 0.03 * s])
        hem = np.array([waist[0], 0.0, (0.33 if p.dress else 0.4) * h])
        parts.append(_Part("skirt", waist, hem, (0.17 * s * g * p.hips, 0.26 * s * g * p.hips, 0.8), "skirt"))
    head = parts[0].start
    if p.hair == "long":
        parts.append(
            _Part(
                "long_hair",
                head + np.array([-0.04, 0, 0.02]) * s,
                head + np.array([-0.06, 0, -0.24]) * s,
                (0.1 * s, 0.11 * s, 0.7),
                "hair",
            )
        )
    elif p.hair == "bun":
        parts.append(
            _Part("bun", head + np.array([-0.085, 0, 0.08]) * s, None, (0.045 * s, 0.045 * s, 0.045 * s), "hair")
        )
    elif p.hair == "ponytail":
        parts.append(
            _Part(
                "ponytail",
                head + np.array([-0.1, 0, 0.04]) * s,
                head + np.array([-0.13, 0, -0.2]) * s,
                (0.035 * s, 0.02 * s, 1.0),
                "hair",
            )
        )
    return parts


def _area(part: _Part) -> float:
    if part.end is None:
        a, b, c = part.radii
        return 4 * np.pi * ((a**1.6 * b**1.6 + a**1.6 * c**1.6 + b**1.6 * c**1.6) / 3) ** (1 / 1.6)
    r = 0.5 * (part.radii[0] + part.radii[1]) * (1 + part.radii[2]) / 2
    return 2 * np.pi * r * float(np.linalg.norm(part.end - part.start))


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``axis``: the first horizontal-ish (width), the second depth."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    depth = helper - axis * (helper @ axis)
    depth /= np.linalg.norm(depth)
    return np.cross(axis, depth), depth


def _sample(part: _Part, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` points on the part's surface: positions, unit normals, and the position along it (0–1)."""
    if part.end is None:
        v = rng.normal(size=(n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        radii = np.asarray(part.radii)
        normal = v / radii
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        return part.start + v * radii, normal, (v[:, 2] + 1) / 2
    axis = part.end - part.start
    length = float(np.linalg.norm(axis))
    unit = axis / length
    width, depth = _frame(unit)
    t = rng.random(n)
    phi = rng.random(n) * 2 * np.pi
    r = part.radii[0] + t * (part.radii[1] - part.radii[0])
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    offset = r[:, None] * (c * width + part.radii[2] * s * depth)
    normal = c * width + s * depth / max(part.radii[2], 1e-3)
    normal -= unit * ((part.radii[1] - part.radii[0]) / length)  # cone slope
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return part.start + t[:, None] * axis + offset, normal, t


def _colours(
    p: AvatarParams, part: _Part, points: np.ndarray, normals: np.ndarray, t: np.ndarray, head: np.ndarray
) -> np.ndarray:
    """Per-point RGB for a part, from the identity's clothing, hair and skin."""
    n = len(points)
    skin, top, bottom = np.array(p.skin), np.array(p.top_colour), np.array(p.bottom_colour)
    out = np.tile(skin, (n, 1))
    top_rgb = np.tile(top, (n, 1))
    if p.pattern == "stripes":
        band = (np.floor(points[:, 2] / p.stripe_m) % 2).astype(bool)
        top_rgb[band] = p.accent_colour
    elif p.pattern == "two_tone":
        top_rgb[points[:, 2] < 0.63 * p.height_m] = p.accent_colour
    region = part.region
    if region == "torso":
        out = top_rgb
        if p.top == "tank":
            bare = np.abs(points[:, 1]) > 0.13 * p.height_m / 1.75 * p.shoulders
            out[bare & (points[:, 2] > 0.78 * p.height_m)] = skin
        low = points[:, 2] < 0.5 * p.height_m
        out[low] = p.bottom_colour if not p.dress else top_rgb[low]
    elif region.endswith("upper_arm"):
        covered = t < (0.55 if p.top == "tshirt" else 1.01) if p.top != "tank" else np.zeros(n, bool)
        out[covered] = top_rgb[covered]
    elif region.endswith("forearm"):
        if p.top == "longsleeve":
            out = top_rgb
    elif region.endswith("thigh"):
        if p.bottom in ("trousers", "shorts"):
            covered = t < (0.6 if p.bottom == "shorts" else 1.01)
            out[covered] = bottom
    elif region.endswith("shin"):
        if p.bottom == "trousers":
            out = np.tile(bottom, (n, 1))
    elif region == "foot":
        out = np.tile(np.array(p.shoe_colour), (n, 1))
    elif region == "skirt":
        out = top_rgb if p.dress else np.tile(bottom, (n, 1))
    elif region == "hair":
        out = np.tile(np.array(p.hair_colour), (n, 1))
    elif region == "head" and p.hair != "bald":
        rel = points - head
        scalp = (rel[:, 2] > 0.02 * p.height_m) | ((rel[:, 0] < -0.02 * p.height_m) & (rel[:, 2] > -0.06 * p.height_m))
        if p.hair == "short":
            scalp &= rel[:, 2] > -0.01 * p.height_m
        out[scalp] = p.hair_colour
    return out


def _skirt_weights(points: np.ndarray, part: _Part) -> tuple[np.ndarray, np.ndarray]:
    """Skirts hang from the pelvis and follow the hips towards the hem (not one leg)."""
    length = float(np.linalg.norm(part.end - part.start))
    down = np.clip((part.start[2] - points[:, 2]) / length, 0.0, 1.0)
    side = np.clip(points[:, 1] / (part.radii[1] + 1e-9), -1.0, 1.0)
    dense = np.zeros((len(points), N_JOINTS))
    dense[:, J["pelvis"]] = 1.0 - 0.6 * down
    dense[:, J["left_hip"]] = 0.6 * down * (1 + side) / 2
    dense[:, J["right_hip"]] = 0.6 * down * (1 - side) / 2
    return top_k(dense)


def _disc_quats(normals: np.ndarray) -> np.ndarray:
    """Rotations whose local z axis is the normal (discs lie in the surface)."""
    helper = np.where(np.abs(normals[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(helper, normals)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normals, u)
    return matrix_to_quat(np.stack([u, v, normals], axis=-1))


def _split(weights: np.ndarray, total: int) -> np.ndarray:
    """Integer counts ∝ ``weights`` summing exactly to ``total`` (largest remainder)."""
    raw = weights / weights.sum() * total
    counts = np.floor(raw).astype(int)
    counts[np.argsort(-(raw - counts), kind="stable")[: total - counts.sum()]] += 1
    return counts


def generate_avatar(
    rng: np.random.Generator, avatar_id: str, n_gaussians: int = 20_000, params: AvatarParams | None = None
) -> AvatarAsset:
    """One procedural identity with exactly ``n_gaussians`` Gaussians (5,000–100,000)."""
    if not 5_000 <= n_gaussians <= 100_000:
        raise ValueError(f"n_gaussians={n_gaussians}: expected 5,000–100,000")
    p = params or sample_params(rng)
    rest = rest_joints(p.height_m)
    parts = _body_parts(p, rest)
    counts = _split(np.array([_area(part) for part in parts]), n_gaussians)
    means, normals, colours, is_skirt = [], [], [], []
    for part, count in zip(parts, counts, strict=True):
        points, normal, t = _sample(part, int(count), rng)
        means.append(points)
        normals.append(normal)
        colours.append(_colours(p, part, points, normal, t, parts[0].start))
        is_skirt.append(np.full(len(points), part.region == "skirt"))
    means, normals, colours, is_skirt = map(np.concatenate, (means, normals, colours, is_skirt))
    means[:, 2] -= means[:, 2].min()  # soles on z = 0
    colours = np.clip(colours * rng.uniform(0.94, 1.06, (len(colours), 1)), 0.0, 1.0)  # fabric/skin texture
    indices, weights = transfer_weights(means, rest, p.height_m)
    if is_skirt.any():
        indices[is_skirt], weights[is_skirt] = _skirt_weights(
            means[is_skirt], next(x for x in parts if x.region == "skirt")
        )
    spacing = np.sqrt(sum(_area(x) for x in parts) / n_gaussians)
    log_scales = np.log(np.tile([0.75 * spacing, 0.75 * spacing, 0.12 * spacing], (n_gaussians, 1)))
    cloud = GaussianCloud(
        means=means.astype(np.float32),
        quats=_disc_quats(normals).astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        opacity_logits=np.full(n_gaussians, 4.0, np.float32),
        sh_dc=((colours - 0.5) / SH_C0).astype(np.float32),
    )
    meta = {
        "source": "procedural",
        "height_m": float(p.height_m),
        "scale": 1.0,
        "generator": {"name": "song.datasets.avatars.generate", "version": GENERATOR_VERSION, **vars(p)},
    }
    return AvatarAsset(avatar_id, cloud, indices, weights, rest.astype(np.float32), meta)


def build_pool(out_dir: str | Path, count: int, seed: int, n_gaussians: int = 20_000) -> list[Path]:
    """Write ``count`` identities ``avatar_{seed}_{i:04d}.avatar.npz``; avatar i depends only on (seed, i)."""
    paths = []
    for index in range(count):
        rng = derive_rng(seed, "avatar", index)
        asset = generate_avatar(rng, f"avatar_{seed}_{index:04d}", n_gaussians)
        asset.meta["generator"].update(seed=seed, index=index)
        paths.append(save_avatar(asset, out_dir))
    return paths
