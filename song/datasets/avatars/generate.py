"""Procedural Gaussian avatars: anthropometric bodies with faces, hands, hair and shaded clothing.

The body is a set of surfaces around the bones of :func:`song.geometry.skeleton.rest_joints` in the
T-pose — tapered elliptic tubes for the torso, limbs and fingers, ellipsoids for the head, nose, ears,
palms, feet and the caps that close the shoulder and hip joints (no seams there) — sized from the
identity's measurements (:mod:`song.datasets.avatars.anthropometry`: stature, shoulder and hip breadth,
chest depth per sex and age group). Gaussians are flat discs on those surfaces (the normal is the thin
axis), their number split between parts in proportion to area (the head and hands denser, so the face
and fingers resolve).

Looks (:func:`_colours`): skin with smooth tone variation, a face (eyes with sclera and iris, brows,
lips, nose and cheeks shaded), hair as a shell with volume in several styles, clothing by region (tops
with short or long sleeves or tanks; trousers, shorts, skirts, dresses) in cotton, knit or denim
textures with folds at the elbows and knees, side seams and hems baked in as shading, shoes with soles,
sometimes glasses, a shoulder bag or a lanyard; then a soft key light from above and in front baked into
the colours (degree-0 colours are what a splat renderer shows from every side, so form comes from this
shading). Skinning weights come from :func:`transfer_weights`, except what hangs from the pelvis (skirts,
dresses, bags), which follows the hips.

Every parameter is drawn from the avatar's own generator (``derive_rng(seed, "avatar", index)``), so
avatar ``i`` of a pool does not depend on the pool's size, and the same seed gives identical files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.avatars.anthropometry import Body, sample_body
from song.datasets.avatars.asset import AvatarAsset, save_avatar
from song.datasets.avatars.skinning import top_k, transfer_weights
from song.datasets.scenes.ply import SH_C0, GaussianCloud
from song.geometry.rotations import matrix_to_quat
from song.geometry.skeleton import JOINT_INDEX as J
from song.geometry.skeleton import JOINT_NAMES, N_JOINTS, rest_joints
from song.util import derive_rng

GENERATOR_VERSION = 6
# The Monk Skin Tone (MST) scale: ten swatches, sRGB, light (MST 1) to deep (MST 10). Monk, E. (2023),
# "The Monk Skin Tone Scale", SocArXiv, doi:10.31235/osf.io/pdf4c; the swatch colours as Google publishes
# them with the scale (skintone.google, CC BY 4.0). Identities draw their place on the scale uniformly
# (docs/avatars.md says why) and take the swatches' colour there, interpolated in linear light.
MST_HEX = ("f6ede4", "f3e7db", "f7ead0", "eadaba", "d7bd96", "a07e56", "825c43", "604134", "3a312a", "292420")
SKIN_TONES = np.array([[int(h[i : i + 2], 16) / 255.0 for i in (0, 2, 4)] for h in MST_HEX])
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
EYE_COLOURS = np.array([[0.22, 0.13, 0.07], [0.35, 0.24, 0.12], [0.25, 0.38, 0.5], [0.3, 0.4, 0.28]])
DENIM = np.array([[0.16, 0.22, 0.38], [0.24, 0.33, 0.52], [0.38, 0.47, 0.62], [0.12, 0.13, 0.16]])
TOPS = ("tshirt", "longsleeve", "tank")
BOTTOMS = ("trousers", "shorts", "skirt")
PATTERNS = ("solid", "stripes", "two_tone")
FABRICS = ("cotton", "knit", "denim")
HAIR = ("short", "long", "bun", "ponytail", "bald", "bob", "curly")
ACCESSORIES = {"glasses": 0.2, "bag": 0.2, "lanyard": 0.1}  # independent chances
HEAD_DENSITY, HAND_DENSITY = 3.0, 2.0  # Gaussians per area relative to the body (faces and fingers resolve)
EYE_DENSITY = 16.0  # Anny's eyeballs
KEY_LIGHT = np.array([0.35, 0.2, 1.0]) / np.linalg.norm([0.35, 0.2, 1.0])
AMBIENT = 0.66  # baked shading: AMBIENT + (1 − AMBIENT) · (½ + ½ n·L)


@dataclass
class AvatarParams:
    """What an identity looks like (all lengths in metres, colours sRGB in [0, 1])."""

    height_m: float
    sex: str
    age_group: str
    biacromial_m: float
    hip_m: float
    chest_depth_m: float
    head_scale: float
    girth: float
    skin: list[float]
    top: str
    bottom: str
    dress: bool
    pattern: str
    top_fabric: str
    bottom_fabric: str
    top_colour: list[float]
    accent_colour: list[float]
    bottom_colour: list[float]
    shoe_colour: list[float]
    sole_colour: list[float]
    hair: str
    hair_colour: list[float]
    eye_colour: list[float]
    accessories: list[str]
    accessory_colour: list[float]
    stripe_m: float = 0.04
    age_years: float = 30.0
    skin_mst: float = 0.0  # place on the Monk Skin Tone scale (1 light – 10 deep)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def body(self) -> Body:
        """The measurements as an anthropometry record."""
        return Body(
            self.sex, self.age_group, self.height_m, self.biacromial_m, self.hip_m, self.chest_depth_m, self.head_scale
        )


def _colour(rng: np.random.Generator) -> list[float]:
    """A clothing colour: random hue, mostly muted saturation, varied value (HSV → RGB)."""
    h, s, v = rng.random(), rng.choice([rng.uniform(0.05, 0.3), rng.uniform(0.35, 0.85)]), rng.uniform(0.15, 0.95)
    k = (np.array([5.0, 3.0, 1.0]) + h * 6.0) % 6.0
    rgb = v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return [round(float(c), 4) for c in rgb]


def skin_colour(mst: float) -> np.ndarray:
    """The sRGB skin colour at a place on the Monk scale (1–10): its swatches mixed in linear light."""
    from song.datasets.scenes.materials import linear_to_srgb, srgb_to_linear

    place = float(np.clip(mst, 1.0, len(SKIN_TONES))) - 1.0
    low = min(int(np.floor(place)), len(SKIN_TONES) - 2)
    t = place - low
    linear = srgb_to_linear(SKIN_TONES[low]) * (1 - t) + srgb_to_linear(SKIN_TONES[low + 1]) * t
    return linear_to_srgb(linear)


def _rounded(values) -> list[float]:
    return [round(float(c), 4) for c in values]


def sample_params(rng: np.random.Generator) -> AvatarParams:
    """Draw one identity's parameters."""
    body = sample_body(rng)
    mst = float(rng.uniform(1.0, len(SKIN_TONES)))
    skin = skin_colour(mst)
    dress = bool(rng.random() < (0.2 if body.sex == "female" else 0.02))
    skirt_p = 0.25 if body.sex == "female" else 0.02
    bottom = "skirt" if dress else str(rng.choice(BOTTOMS, p=[0.78 - skirt_p, 0.22, skirt_p]))
    bottom_fabric = "denim" if bottom != "skirt" and rng.random() < 0.45 else str(rng.choice(["cotton", "knit"]))
    bottom_colour = DENIM[rng.integers(len(DENIM))] if bottom_fabric == "denim" else _colour(rng)
    hair_p = (
        [0.3, 0.22, 0.1, 0.12, 0.06, 0.12, 0.08] if body.sex == "female" else [0.55, 0.04, 0.02, 0.03, 0.2, 0.04, 0.12]
    )
    grey = body.age_group == "older" and rng.random() < 0.7
    hair_colour = (
        HAIR_COLOURS[-1] * rng.uniform(0.9, 1.2) if grey else HAIR_COLOURS[rng.integers(len(HAIR_COLOURS) - 1)]
    )
    accessories = [name for name, chance in ACCESSORIES.items() if rng.random() < chance]
    return AvatarParams(
        height_m=body.stature_m,
        sex=body.sex,
        age_group=body.age_group,
        biacromial_m=body.biacromial_m,
        hip_m=body.hip_m,
        chest_depth_m=body.chest_depth_m,
        head_scale=body.head_scale,
        girth=round(float(np.clip(rng.normal(1.0, 0.07), 0.85, 1.25)), 4),
        skin=_rounded(skin),
        skin_mst=round(mst, 3),
        top=str(rng.choice(TOPS, p=[0.5, 0.38, 0.12])),
        bottom=bottom,
        dress=dress,
        pattern=str(rng.choice(PATTERNS, p=[0.55, 0.25, 0.2])),
        top_fabric=str(rng.choice(FABRICS, p=[0.6, 0.28, 0.12])),
        bottom_fabric=bottom_fabric,
        top_colour=_colour(rng),
        accent_colour=_colour(rng),
        bottom_colour=_rounded(np.clip(np.asarray(bottom_colour) * rng.uniform(0.85, 1.1), 0, 1)),
        shoe_colour=_colour(rng),
        sole_colour=_rounded(rng.choice([[0.92, 0.91, 0.88], [0.12, 0.11, 0.1], [0.55, 0.42, 0.3]])),
        hair=str(rng.choice(HAIR, p=hair_p)),
        hair_colour=_rounded(np.clip(hair_colour, 0, 1)),
        eye_colour=_rounded(EYE_COLOURS[rng.integers(len(EYE_COLOURS))]),
        accessories=accessories,
        accessory_colour=_colour(rng),
        stripe_m=round(float(rng.uniform(0.025, 0.06)), 4),
        age_years=_age_years(body, rng),
    )


def _age_years(body: Body, rng: np.random.Generator) -> float:
    """Age: a child's from its stature on the CDC curve (6–12), an adult's 20–64, an older adult's 65–85."""
    from song.datasets.avatars import anthropometry as a

    if body.age_group == "child":
        years = a.CHILD_AGE[0] + (body.stature_m - a.CHILD_STATURE_AT_6_M) / a.CHILD_GROWTH_M_PER_YEAR
        return round(float(np.clip(years, *a.CHILD_AGE)), 2)
    return round(float(rng.uniform(20.0, 64.0) if body.age_group == "adult" else rng.uniform(65.0, 85.0)), 2)


# ---- surfaces -------------------------------------------------------------------------------------
@dataclass
class _Part:
    """A surface: a tapered elliptic tube between two points, or an ellipsoid (``end`` None)."""

    name: str
    start: np.ndarray
    end: np.ndarray | None
    radii: tuple[float, float, float]  # tube: (r0, r1, depth/width ratio); ellipsoid: semi-axes (x, y, z)
    region: str
    density: float = 1.0  # Gaussians per area relative to the body


def _head_centre(p: AvatarParams, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Head ellipsoid centre and semi-axes (the top stays at the stature for larger child heads)."""
    s, k = p.height_m / 1.75, p.head_scale
    radii = np.array([0.1, 0.085, 0.115]) * s * k
    centre = rest[J["head"]] + np.array([0.012, 0.0, 0.104]) * s
    centre[2] -= (k - 1.0) * 0.115 * s
    return centre, radii


def _tube(rest: np.ndarray, s: float, g: float, name, a, b, r0, r1, region, flat=1.0, density=1.0) -> _Part:
    """A tapered tube between two joints (or points), radii scaled by height and girth."""
    return _Part(
        name,
        rest[J[a]] if isinstance(a, str) else np.asarray(a, float),
        rest[J[b]] if isinstance(b, str) else np.asarray(b, float),
        (r0 * s * g, r1 * s * g, flat),
        region,
        density,
    )


def _blob(name, centre, radii, region, density=1.0) -> _Part:
    """An ellipsoid."""
    return _Part(name, np.asarray(centre, float), None, tuple(float(r) for r in radii), region, density)


def _body_parts(p: AvatarParams, rest: np.ndarray) -> list[_Part]:
    """The body's parts in a fixed order: head, neck, torso; each side's limbs; clothing layers, hair, accessories."""
    h, g = p.height_m, p.girth
    s = h / 1.75

    def tube(*args, **kwargs) -> _Part:
        return _tube(rest, s, g, *args, **kwargs)

    blob = _blob

    pelvis, neck = rest[J["pelvis"]], rest[J["neck"]]
    hc, hr = _head_centre(p, rest)
    chest_half = 0.42 * p.biacromial_m  # torso half-width under the shoulders (deltoids included)
    waist_half = 0.48 * p.hip_m
    flat = float(np.clip(p.chest_depth_m / (2 * chest_half), 0.5, 0.85))
    parts = [
        blob("head", hc, hr, "head", HEAD_DENSITY),
        blob(
            "nose",
            hc + np.array([0.96 * hr[0], 0.0, -0.12 * hr[2]]),
            np.array([0.024, 0.016, 0.032]) * s,
            "nose",
            HEAD_DENSITY,
        ),
        tube("neck", "neck", hc - np.array([0, 0, 0.05 * s]), 0.05, 0.048, "neck"),
        _Part(
            "torso",
            pelvis - np.array([0, 0, 0.06 * s]),
            neck - np.array([0, 0, 0.03 * s]),
            (waist_half * g, chest_half * g, flat),
            "torso",
        ),
        tube("shoulders", "left_shoulder", "right_shoulder", 0.055, 0.055, "torso"),
    ]
    for side, sign in (("left", 1.0), ("right", -1.0)):
        parts += _side_parts(p, rest, side, sign, hc, hr)
    return parts + _layer_parts(p, rest, hc, hr, waist_half)  # fmt: skip


def _side_parts(
    p: AvatarParams, rest: np.ndarray, side: str, sign: float, hc: np.ndarray, hr: np.ndarray
) -> list[_Part]:
    """One side's ear, arm, hand, hip, leg and foot."""
    g, s = p.girth, p.height_m / 1.75

    def tube(*args, **kwargs) -> _Part:
        return _tube(rest, s, g, *args, **kwargs)

    blob = _blob
    shoulder, wrist, hand = rest[J[f"{side}_shoulder"]], rest[J[f"{side}_wrist"]], rest[J[f"{side}_hand"]]
    return [
        blob(f"{side}_ear", hc + np.array([-0.05 * hr[0], sign * 0.97 * hr[1], -0.05 * hr[2]]), np.array([0.02, 0.011, 0.03]) * s * p.head_scale, "ear", HEAD_DENSITY),
        blob(f"{side}_shoulder_cap", shoulder + np.array([0, sign * 0.01 * s, 0]), np.array([0.058, 0.06, 0.06]) * s * g, f"{side}_shoulder_cap"),
        tube(f"{side}_upper_arm", f"{side}_shoulder", f"{side}_elbow", 0.048, 0.04, f"{side}_upper_arm"),
        tube(f"{side}_forearm", f"{side}_elbow", f"{side}_wrist", 0.039, 0.031, f"{side}_forearm"),
        blob(f"{side}_palm", 0.45 * wrist + 0.55 * hand, np.array([0.042, 0.045, 0.017]) * s, "hand", HAND_DENSITY),
        tube(f"{side}_fingers", hand, hand + np.array([0.0, sign * 0.085 * s, -0.004 * s]), 0.016 / g, 0.013 / g, "fingers", 2.5, HAND_DENSITY),
        tube(f"{side}_thumb", wrist + np.array([0.025, sign * 0.035, -0.004]) * s, wrist + np.array([0.065, sign * 0.07, -0.01]) * s, 0.011 / g, 0.009 / g, "hand", 1.0, HAND_DENSITY),
        blob(f"{side}_hip_cap", rest[J[f"{side}_hip"]] + np.array([0, sign * 0.015 * s, -0.01 * s]), np.array([0.085, 0.08, 0.08]) * s * g * (p.hip_m / 0.35), f"{side}_hip_cap"),
        tube(f"{side}_thigh", f"{side}_hip", f"{side}_knee", 0.08 * p.hip_m / 0.35, 0.056, f"{side}_thigh"),
        tube(f"{side}_shin", f"{side}_knee", f"{side}_ankle", 0.054, 0.038, f"{side}_shin"),
        blob(
            f"{side}_foot",
            0.5 * (rest[J[f"{side}_ankle"]] + rest[J[f"{side}_foot"]]) + np.array([0.01, 0, -0.01]) * s,
            np.array([0.12, 0.048, 0.04]) * s,
            "foot",
        ),
    ]  # fmt: skip


def _layer_parts(
    p: AvatarParams,
    rest: np.ndarray,
    hc: np.ndarray,
    hr: np.ndarray,
    waist_half: float,
    eyes: np.ndarray | None = None,
) -> list[_Part]:
    """Skirt, hair and accessories over the body (``eyes``: the body's eyeball centres, if it has any)."""
    h, g = p.height_m, p.girth
    s = h / 1.75
    pelvis = rest[J["pelvis"]]
    blob = _blob
    parts: list[_Part] = []
    if p.bottom == "skirt":
        waist = pelvis + np.array([0, 0, 0.03 * s])
        hem = np.array([waist[0], 0.0, (0.33 if p.dress else 0.4) * h])
        parts.append(_Part("skirt", waist, hem, (waist_half * g * 1.03, waist_half * g * 1.55, 0.8), "skirt"))
    if p.hair != "bald":
        volume = {"curly": 1.16, "bob": 1.1}.get(p.hair, 1.07)
        parts.append(blob("hair", hc + np.array([-0.01, 0.0, 0.01]) * s, hr * volume, "hair", HEAD_DENSITY))
    if p.hair == "long":
        parts.append(
            _Part(
                "long_hair",
                hc + np.array([-0.05, 0, 0.0]) * s,
                hc + np.array([-0.07, 0, -0.26]) * s,
                (0.1 * s, 0.11 * s, 0.6),
                "hair",
            )
        )
    elif p.hair == "bun":
        parts.append(blob("bun", hc + np.array([-0.09, 0, 0.08]) * s, np.array([0.045, 0.045, 0.045]) * s, "hair"))
    elif p.hair == "ponytail":
        parts.append(
            _Part(
                "ponytail",
                hc + np.array([-0.1, 0, 0.04]) * s,
                hc + np.array([-0.13, 0, -0.2]) * s,
                (0.035 * s, 0.02 * s, 1.0),
                "hair",
            )
        )
    if "bag" in p.accessories:
        centre = pelvis + np.array([-0.01, waist_half * g + 0.05 * s, 0.0])  # on the left hip
        parts.append(blob("bag", centre, np.array([0.1, 0.045, 0.12]) * s, "bag"))
    if "glasses" in p.accessories:
        for side in (1.0, -1.0):
            eye = hc + hr * _EYE_DIR * np.array([1.0, side, 1.0]) if eyes is None else eyes[0 if side > 0 else 1]
            if eyes is not None:
                eye = eye + np.array([0.01 * s, 0.0, 0.0])  # in front of the eyeball, not on it
            parts.append(
                _Part(
                    f"lens_{side:+.0f}",
                    eye + np.array([0.012 * s, 0, 0]),
                    eye + np.array([0.016 * s, 0, 0]),
                    (0.022 * s, 0.022 * s, 1.0),
                    "glasses",
                    HEAD_DENSITY,
                )
            )
    return parts  # fmt: skip


_EYE_DIR = np.array([0.82, 0.36, 0.16]) / np.linalg.norm([0.82, 0.36, 0.16])


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


def _sphere_lattice(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` evenly spread unit vectors: a Fibonacci lattice turned by a random rotation.

    Evenly spread rather than independent: discs placed independently leave gaps (a Poisson process
    covers a surface unevenly) through which the inside of the head and hair shows as dark cracks.
    """
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    lattice = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    q, upper = np.linalg.qr(rng.normal(size=(3, 3)))
    return lattice @ (q * np.sign(np.diag(upper))).T


def _plane_lattice(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` evenly spread points of the unit square (the R2 sequence from a random start), as two arrays."""
    g = 1.32471795724474602596  # the plastic number: R2's generator
    i = np.arange(1, n + 1)[:, None]
    points = (rng.random(2) + i * np.array([1.0 / g, 1.0 / g**2])) % 1.0
    return points[:, 0], points[:, 1]


def _sample(part: _Part, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` points on the part's surface.

    Returns positions, unit normals, the position along the part (0–1), and the surface direction (the
    unit-sphere point for ellipsoids; the angle around a tube as (cos, sin, 0)).
    """
    if part.end is None:
        v = _sphere_lattice(n, rng)
        radii = np.asarray(part.radii)
        normal = v / radii
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        return part.start + v * radii, normal, (v[:, 2] + 1) / 2, v
    axis = part.end - part.start
    length = float(np.linalg.norm(axis))
    unit = axis / length
    width, depth = _frame(unit)
    t, phi = _plane_lattice(n, rng)
    phi = phi * 2 * np.pi
    r = part.radii[0] + t * (part.radii[1] - part.radii[0])
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    offset = r[:, None] * (c * width + part.radii[2] * s * depth)
    normal = c * width + s * depth / max(part.radii[2], 1e-3)
    normal -= unit * ((part.radii[1] - part.radii[0]) / length)  # cone slope
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return part.start + t[:, None] * axis + offset, normal, t, np.column_stack([c[:, 0], s[:, 0], np.zeros(n)])


def _hair_mask(p: AvatarParams, v: np.ndarray) -> np.ndarray:
    """Which points of the hair shell (unit directions from the head centre) carry hair."""
    front = v[:, 0] > 0.3
    line = {"short": -0.25, "curly": -0.3, "bob": -0.6, "long": -0.55, "bun": -0.3, "ponytail": -0.3}[p.hair]
    keep = v[:, 2] > line
    keep &= ~front | (v[:, 2] > 0.5)  # the forehead hairline
    if p.hair in ("bob", "long"):
        keep &= ~(front & (np.abs(v[:, 1]) < 0.55) & (v[:, 2] < 0.5))  # the face stays open
    return keep


# ---- looks ----------------------------------------------------------------------------------------
def _ellipse(v: np.ndarray, cy: float, cz: float, ry: float, rz: float) -> np.ndarray:
    return (v[:, 0] > 0.45) & (((v[:, 1] - cy) / ry) ** 2 + ((v[:, 2] - cz) / rz) ** 2 < 1.0)


def _soft(v: np.ndarray, cy: float, cz: float, ry: float, rz: float) -> np.ndarray:
    """A smooth bump on the head's front: 1 at (cy, cz), falling off as a Gaussian of radii (ry, rz)."""
    return (v[:, 0] > 0.3) * np.exp(-(((v[:, 1] - cy) / ry) ** 2 + ((v[:, 2] - cz) / rz) ** 2))


def _face(p: AvatarParams, v: np.ndarray, out: np.ndarray) -> None:
    """A face on the head's front (``v``: unit directions, x forward).

    First the shading a face's relief gets under light from above (eye sockets under the brow ridge, the
    sides of the nose, under the nose and the lower lip), then eyes (sclera, iris, pupil, the upper lid's
    lash line), brows, lips and cheeks.
    """
    skin = np.array(p.skin)
    ez = _EYE_DIR[2]
    shade = 1.0 - 0.42 * (_soft(v, _EYE_DIR[1], ez - 0.01, 0.17, 0.1) + _soft(v, -_EYE_DIR[1], ez - 0.01, 0.17, 0.1))
    shade -= 0.22 * (_soft(v, 0.11, -0.1, 0.05, 0.12) + _soft(v, -0.11, -0.1, 0.05, 0.12))  # beside the nose
    shade -= 0.25 * _soft(v, 0.0, -0.22, 0.09, 0.035) + 0.2 * _soft(v, 0.0, -0.43, 0.14, 0.04)  # under nose, lip
    shade += 0.06 * _soft(v, 0.0, ez + 0.02, 0.06, 0.2)  # the bridge of the nose catches the light
    dark = 1.0 - np.clip(shade, 0.45, 1.1)[:, None]
    out *= 1.0 - dark * [0.85, 1.0, 1.05]  # shadow on skin is warm: red light scatters under it
    # the sheen of skin where the face turns to the light (forehead, nose bridge, cheekbones): what gives
    # a dark face its contrast, as shadow does a fair one
    sheen = _soft(v, 0.0, 0.42, 0.3, 0.1) + _soft(v, 0.0, ez - 0.02, 0.05, 0.12)
    sheen = sheen + _soft(v, 0.36, -0.06, 0.1, 0.06) + _soft(v, -0.36, -0.06, 0.1, 0.06)
    out += (0.35 * np.clip(sheen, 0.0, 1.0))[:, None] * (1.0 - out) * (1.0 - np.mean(skin))
    for side in (1.0, -1.0):
        ey = side * _EYE_DIR[1]
        out[_ellipse(v, ey, ez, 0.11, 0.045)] = [0.78, 0.75, 0.72]
        out[_ellipse(v, ey, ez, 0.055, 0.045)] = np.array(p.eye_colour) * 0.7
        out[_ellipse(v, ey, ez, 0.025, 0.025)] = [0.03, 0.03, 0.03]
        out[_ellipse(v, ey, ez + 0.04, 0.12, 0.016)] = [0.1, 0.07, 0.06]  # the lash line
        brow = np.array(p.hair_colour) * 0.6 if np.mean(p.hair_colour) < 0.6 else skin * 0.55
        out[_ellipse(v, side * 0.35, ez + 0.13, 0.15, 0.034)] = brow
        cheek = _ellipse(v, side * 0.42, -0.12, 0.14, 0.1)
        out[cheek] = out[cheek] * [1.02, 0.95, 0.94]
    out[_ellipse(v, 0.0, -0.33, 0.19, 0.04)] = skin * [0.7, 0.45, 0.45]
    out[_ellipse(v, 0.0, -0.31, 0.18, 0.013)] = skin * [0.4, 0.25, 0.25]  # the line between the lips


def _fabric(kind: str, points: np.ndarray, around: np.ndarray) -> np.ndarray:
    """A multiplicative texture: denim twill, knit ribs or cotton (smooth, faint)."""
    z = points[:, 2]
    arc = np.arctan2(around[:, 1], around[:, 0]) * 0.05  # metres around a tube of ~5 cm radius
    if kind == "denim":
        return 1.0 + 0.07 * np.sin(2 * np.pi * (z + arc) / 0.0045) - 0.04 * np.sin(2 * np.pi * z / 0.37) ** 2
    if kind == "knit":
        return 1.0 + 0.08 * np.sin(2 * np.pi * arc / 0.006)
    return 1.0 + 0.025 * np.sin(2 * np.pi * (points[:, 0] * 7 + z * 11)) * np.sin(2 * np.pi * points[:, 1] * 9)


def _folds(t: np.ndarray, near_start: bool, near_end: bool) -> np.ndarray:
    """Horizontal creases near the joint ends of a sleeve or trouser leg."""
    weight = np.zeros_like(t)
    if near_end:
        weight = np.maximum(weight, np.exp(-(((t - 1.0) / 0.18) ** 2)))
    if near_start:
        weight = np.maximum(weight, np.exp(-((t / 0.18) ** 2)))
    return 1.0 - 0.14 * weight * np.sin(2 * np.pi * t * 9) ** 2


@dataclass(frozen=True)
class _Cloth:
    """The colours a part's points start from: skin (with its tone), the top and bottom garments, side seams."""

    skin: np.ndarray
    tone: np.ndarray
    top: np.ndarray
    bottom: np.ndarray
    seam: np.ndarray

    @property
    def bare(self) -> np.ndarray:
        return self.skin * self.tone[:, None]


def _colours(
    p: AvatarParams, part: _Part, points: np.ndarray, normals: np.ndarray, t: np.ndarray, v: np.ndarray
) -> np.ndarray:
    """Per-point RGB for a part (before the baked light), from the identity's clothing, hair and skin."""
    n = len(points)
    skin, bottom = np.array(p.skin), np.array(p.bottom_colour)
    tone = 1.0 + 0.035 * np.sin(points[:, 0] * 23 + 1.3) * np.sin(points[:, 1] * 19) * np.sin(points[:, 2] * 17 + 0.7)
    top_rgb = np.tile(np.array(p.top_colour), (n, 1))
    if p.pattern == "stripes":
        top_rgb[(np.floor(points[:, 2] / p.stripe_m) % 2).astype(bool)] = p.accent_colour
    elif p.pattern == "two_tone":
        top_rgb[points[:, 2] < 0.63 * p.height_m] = p.accent_colour
    top_rgb *= _fabric(p.top_fabric, points, v)[:, None]
    bottom_rgb = bottom * _fabric(p.bottom_fabric, points, v)[:, None]
    seam = np.abs(v[:, 1]) < 0.06  # the sides of a vertical tube (its width axis is lateral)
    cloth = _Cloth(skin, tone, top_rgb, bottom_rgb, seam)
    region = part.region
    if region == "torso":
        return _torso_colours(p, cloth, points)
    if region.endswith(("shoulder_cap", "upper_arm", "forearm")):
        return _arm_colours(p, cloth, region, t)
    if region.endswith(("hip_cap", "thigh", "shin")) or region in ("foot", "skirt"):
        return _leg_colours(p, cloth, region, points, t, v)
    return _head_and_kit_colours(p, cloth, region, points, normals, t, v)


def _torso_colours(p: AvatarParams, cloth: _Cloth, points: np.ndarray) -> np.ndarray:
    """The top, the bottom below the waist (or a dress), a belt, a bag's strap, a lanyard and badge."""
    skin, top_rgb, bottom_rgb, seam, h = cloth.skin, cloth.top, cloth.bottom, cloth.seam, p.height_m
    out = top_rgb.copy()
    out[seam] *= 0.84
    if p.top == "tank":
        bare = np.abs(points[:, 1]) > 0.3 * p.biacromial_m
        out[bare & (points[:, 2] > 0.78 * h)] = skin
    low = points[:, 2] < 0.5 * h
    out[low] = bottom_rgb[low] if not p.dress else top_rgb[low]
    belt = np.abs(points[:, 2] - 0.5 * h) < 0.012 * h
    if not p.dress:
        out[belt] *= 0.6
    if "bag" in p.accessories:  # the strap across the chest
        strap = np.abs(points[:, 2] - (0.72 * h - 0.9 * points[:, 1])) < 0.018
        out[strap & (points[:, 0] > 0) & (points[:, 2] > 0.52 * h)] = np.array(p.accessory_colour) * 0.7
    if "lanyard" in p.accessories:
        band = (np.abs(np.abs(points[:, 1]) - (points[:, 2] - 0.66 * h) * 0.45) < 0.008) & (points[:, 2] > 0.66 * h)
        out[band & (points[:, 0] > 0)] = p.accessory_colour
        badge = (np.abs(points[:, 1]) < 0.03) & (np.abs(points[:, 2] - 0.645 * h) < 0.04) & (points[:, 0] > 0)
        out[badge] = [0.95, 0.95, 0.93]
    return out


def _arm_colours(p: AvatarParams, cloth: _Cloth, region: str, t: np.ndarray) -> np.ndarray:
    """Shoulder caps, sleeves (with folds and hems) over bare arms."""
    n, skin, tone, top_rgb, out = len(t), cloth.skin, cloth.tone, cloth.top, cloth.bare
    if region.endswith("shoulder_cap"):
        out = skin * tone[:, None] if p.top == "tank" else top_rgb
    elif region.endswith("upper_arm"):
        covered = t < (0.55 if p.top == "tshirt" else 1.01) if p.top != "tank" else np.zeros(n, bool)
        sleeve = top_rgb * _folds(t, False, p.top == "longsleeve")[:, None]
        if p.top == "tshirt":
            sleeve[(t > 0.5) & (t < 0.55)] *= 0.8  # the hem
        out[covered] = sleeve[covered]
    elif region.endswith("forearm"):
        if p.top == "longsleeve":
            out = top_rgb * _folds(t, True, False)[:, None]
            out[t > 0.95] *= 0.82  # the cuff
    return out


def _leg_colours(
    p: AvatarParams, cloth: _Cloth, region: str, points: np.ndarray, t: np.ndarray, v: np.ndarray
) -> np.ndarray:
    """Hips, trousers or shorts (folds, seams, hems), bare legs under a skirt, shoes, the skirt itself."""
    n, h, skin, tone, out = len(t), p.height_m, cloth.skin, cloth.tone, cloth.bare
    top_rgb, bottom_rgb, seam = cloth.top, cloth.bottom, cloth.seam
    if region.endswith("hip_cap"):
        out = bottom_rgb if not p.dress else top_rgb
    elif region.endswith("thigh"):
        if p.bottom in ("trousers", "shorts"):
            covered = t < (0.6 if p.bottom == "shorts" else 1.01)
            legs = bottom_rgb * _folds(t, False, p.bottom == "trousers")[:, None]
            legs[seam] *= 0.84
            if p.bottom == "shorts":
                legs[(t > 0.55) & (t < 0.6)] *= 0.8
            out[covered] = legs[covered]
        elif p.bottom == "skirt":
            out = skin * tone[:, None]
    elif region.endswith("shin"):
        if p.bottom == "trousers":
            out = bottom_rgb * _folds(t, True, False)[:, None]
            out[seam] *= 0.84
            out[t > 0.93] *= 0.82
    elif region == "foot":
        out = np.tile(np.array(p.shoe_colour), (n, 1))
        out[points[:, 2] < points[:, 2].min() + 0.012 * h] = p.sole_colour
    elif region == "skirt":
        pleats = 1.0 - 0.1 * np.sin(np.arctan2(v[:, 1], v[:, 0]) * 14) ** 2
        out = (top_rgb if p.dress else bottom_rgb) * pleats[:, None]
    return out


def _head_and_kit_colours(
    p: AvatarParams, cloth: _Cloth, region: str, points: np.ndarray, normals: np.ndarray, t: np.ndarray, v: np.ndarray
) -> np.ndarray:
    """Hair, the face, nose, ears, fingers (creases and nails), a bag, glasses; bare skin elsewhere (palms)."""
    n, out = len(t), cloth.bare
    if region == "hair":
        curls = 1.0 + (0.12 if p.hair == "curly" else 0.06) * np.sin(points[:, 2] * 260) * np.sin(points[:, 1] * 240)
        out = np.array(p.hair_colour) * curls[:, None]
    elif region == "head":
        _face(p, v, out)
    elif region == "nose":
        out[normals[:, 2] < -0.6] *= 0.8  # the nostrils' shadow
    elif region == "ear":
        out *= 0.93
    elif region == "fingers":
        across = 2.0 * v[:, 1]  # −2…2 across the hand's width
        gaps = (np.abs(across - np.round(across)) < 0.12) & (np.abs(across) < 1.5)  # three creases: four fingers
        out[gaps & (t > 0.25)] *= 0.72
        out[t > 0.93] *= [1.05, 0.95, 0.93]  # nails
    elif region == "bag":
        out = np.tile(np.array(p.accessory_colour), (n, 1))
        out[np.abs(v[:, 2] - 0.55) < 0.04] *= 0.7  # the flap
    elif region == "glasses":
        out = np.tile([0.08, 0.08, 0.09], (n, 1))
    return out


def _shade(colours: np.ndarray, normals: np.ndarray, points: np.ndarray, height: float) -> np.ndarray:
    """Bake a soft key light from above and in front, and a little darkening towards the feet."""
    lit = AMBIENT + (1.0 - AMBIENT) * (0.5 + 0.5 * normals @ KEY_LIGHT)
    ground = 0.9 + 0.1 * np.clip(points[:, 2] / (0.3 * height), 0.0, 1.0)
    return colours * (lit * ground)[:, None]


def _pelvis_weights(points: np.ndarray, top: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """What hangs from the pelvis (skirts, bags) follows the hips towards its lower end (not one leg)."""
    down = np.clip((top - points[:, 2]) / max(length, 1e-6), 0.0, 1.0)
    side = np.clip(points[:, 1] / (np.abs(points[:, 1]).max() + 1e-9), -1.0, 1.0)
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


def _inside(part: _Part, points: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Which points lie inside a part's volume, and their unit directions from its centre (None for a tube)."""
    if part.end is None:
        u = (points - part.start) / np.asarray(part.radii)
        r = np.linalg.norm(u, axis=1)
        return r < 1.0, u / np.maximum(r, 1e-9)[:, None]
    axis = part.end - part.start
    length = float(np.linalg.norm(axis))
    width, depth = _frame(axis / length)
    rel = points - part.start
    t = rel @ axis / length**2
    r = part.radii[0] + np.clip(t, 0.0, 1.0) * (part.radii[1] - part.radii[0])
    across = ((rel @ width) / r) ** 2 + ((rel @ depth) / (r * part.radii[2])) ** 2
    return (t >= 0.0) & (t <= 1.0) & (across < 1.0), None


def _layer_colours(p: AvatarParams, parts: list[_Part], regions: np.ndarray, means: np.ndarray, colours) -> None:
    """Where layers interpenetrate, a surfel takes the colour of what covers it (in place).

    What the hair covers (the scalp, the neck under long hair) takes the hair's colour in its shade, and a
    hair surfel inside the body (long hair reaching into the shoulders) the colour of the nearest body
    surfel: a surfel showing through a gap between the covering surfels then reads as the layer on top,
    not as a speckle of skin in the hair or of hair on a shirt.
    """
    from scipy.spatial import cKDTree

    hair = regions == "hair"
    if not hair.any():
        return
    covered = np.zeros(len(means), bool)
    for part in parts:
        if part.region == "hair":
            inside, direction = _inside(part, means)
            if part.end is None:
                inside &= _hair_mask(p, direction)
            covered |= inside & ~hair
    sunk = np.zeros(len(means), bool)
    for part in parts:
        if part.region not in ("hair", "head", "nose", "ear"):
            sunk |= _inside(part, means)[0] & hair
    colours[covered] = np.array(p.hair_colour) * 0.8
    if sunk.any():
        body = np.flatnonzero(~hair)
        colours[sunk] = colours[body[cKDTree(means[body]).query(means[sunk])[1]]]


def _hair_styled(p: AvatarParams, v: np.ndarray) -> np.ndarray:
    """Where a hair layer's surfels go (``v``: unit directions in the shell): the style and the nape."""
    return _hair_mask(p, v) | ((v[:, 0] < -0.3) & (v[:, 2] > -0.7))


def _sample_part(p: AvatarParams, part: _Part, count: int, rng: np.random.Generator):
    """``count`` surface points of a part; the hair shell keeps only its styled region (oversampled)."""
    if part.name != "hair":
        return _sample(part, count, rng)
    share = float(_hair_mask(p, _sphere_lattice(4096, rng)).mean())  # the styled share of the shell
    n = int(np.ceil(count / max(share, 1e-3) * 1.03))
    while True:  # one even lattice over the whole shell whose styled region holds ≥ count points
        pts, nrm, t, v = _sample(part, n, rng)
        kept = np.flatnonzero(_hair_styled(p, v))
        if len(kept) >= count:
            break
        n = int(np.ceil(n * 1.05))
    kept = np.sort(rng.choice(kept, count, replace=False))  # drops the few percent over
    return pts[kept], nrm[kept], t[kept], v[kept]


@dataclass
class _Surfels:
    """An identity's Gaussians before the baked light: positions, normals, colours, spacing, skinning."""

    means: np.ndarray
    normals: np.ndarray
    colours: np.ndarray
    spacing: np.ndarray
    indices: np.ndarray
    weights: np.ndarray
    body_radius_m: float
    extra: dict[str, Any]


def _procedural_surfels(p: AvatarParams, rest: np.ndarray, n: int, rng: np.random.Generator) -> _Surfels:
    """The procedural body: tubes and ellipsoids around the bones, weights by bone distance."""
    parts = _body_parts(p, rest)
    areas = np.array([_area(part) for part in parts])
    counts = _split(areas * np.array([part.density for part in parts]), n)
    means, normals, colours, spacing, hanging, regions = _part_surfels(
        p, parts, counts, areas, lambda part, count: _sample_part(p, part, count, rng)
    )
    _layer_colours(p, parts, regions, means, colours)
    means[:, 2] -= means[:, 2].min()  # soles on z = 0
    indices, weights = transfer_weights(means, rest, p.height_m)
    _hang_from_pelvis(p, rest, means, hanging, indices, weights)
    return _Surfels(means, normals, colours, spacing, indices, weights, p.body.body_radius_m, {})


def _part_surfels(p: AvatarParams, parts: list[_Part], counts, areas, sample):
    """Points, normals, colours, spacing, hanging flags and regions of ``parts`` (``sample(part, count)``)."""
    means, normals, colours, spacing, hanging, regions = [], [], [], [], [], []
    for part, count, area in zip(parts, counts, areas, strict=True):
        points, normal, t, v = sample(part, int(count))
        means.append(points)
        normals.append(normal)
        colours.append(_colours(p, part, points, normal, t, v))
        spacing.append(np.full(len(points), np.sqrt(area / max(int(count), 1))))
        hanging.append(np.full(len(points), part.region in ("skirt", "bag")))
        regions.append(np.full(len(points), part.region))
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool), np.zeros(0, str)
    return tuple(np.concatenate(x) for x in (means, normals, colours, spacing, hanging, regions))


def _hang_from_pelvis(p, rest, means, hanging, indices, weights) -> None:
    """Skirts and bags follow the hips (in place)."""
    if hanging.any():
        top = float(rest[J["pelvis"], 2] + 0.03 * p.height_m / 1.75)
        indices[hanging], weights[hanging] = _pelvis_weights(means[hanging], top, top - 0.33 * p.height_m)


# ---- the Anny body ---------------------------------------------------------------------------------
_MESH_REGION = {  # dominant joint → the colour region of the procedural parts it replaces
    "pelvis": "torso",
    "spine1": "torso",
    "spine2": "torso",
    "spine3": "torso",
    "left_collar": "torso",
    "right_collar": "torso",
    "neck": "neck",
    "head": "head",
    "left_shoulder": "left_upper_arm",
    "right_shoulder": "right_upper_arm",
    "left_elbow": "left_forearm",
    "right_elbow": "right_forearm",
    "left_wrist": "hand",
    "right_wrist": "hand",
    "left_hand": "hand",
    "right_hand": "hand",
    "left_hip": "left_thigh",
    "right_hip": "right_thigh",
    "left_knee": "left_shin",
    "right_knee": "right_shin",
    "left_ankle": "foot",
    "right_ankle": "foot",
    "left_foot": "foot",
    "right_foot": "foot",
}
_MESH_BONE = {  # a limb region's bone (start, end joints): where along it and around it a point lies
    "torso": ("pelvis", "neck"),
    "left_upper_arm": ("left_shoulder", "left_elbow"),
    "right_upper_arm": ("right_shoulder", "right_elbow"),
    "left_forearm": ("left_elbow", "left_wrist"),
    "right_forearm": ("right_elbow", "right_wrist"),
    "left_thigh": ("left_hip", "left_knee"),
    "right_thigh": ("right_hip", "right_knee"),
    "left_shin": ("left_knee", "left_ankle"),
    "right_shin": ("right_knee", "right_ankle"),
}


def _anny_z(p: AvatarParams) -> dict[str, float]:
    """The identity's z-scores that choose Anny's height, weight and muscle (adults; children sit at 0)."""
    from song.datasets.avatars.anthropometry import ANSUR_II

    if p.age_group == "child":
        return {"weight": (p.girth - 1.0) / 0.07}
    table = ANSUR_II[p.sex]
    return {
        "height": (p.height_m - table["stature"][0]) / table["stature"][1],
        "weight": 0.5 * (p.girth - 1.0) / 0.07 + 0.5 * (p.hip_m - table["hip"][0]) / table["hip"][1],
        "muscle": (p.biacromial_m - table["biacromial"][0]) / table["biacromial"][1],
    }


def _mesh_density(mesh) -> np.ndarray:
    """Gaussians per area of each face relative to the body: head and hands denser, the eyes densest.

    A pupil is ~4 mm across: it takes fine discs to show.
    """
    region = mesh.face_region
    return np.select(
        [region == "eye", region == "head", region == "hand"], [EYE_DENSITY, HEAD_DENSITY, HAND_DENSITY], 1.0
    )


def _weighted_areas(mesh) -> np.ndarray:
    """Each face's area times its :func:`_mesh_density`: its share of the body's Gaussians."""
    tri = mesh.vertices[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return area * _mesh_density(mesh)


def _mesh_sample(mesh, count: int, rng: np.random.Generator, where: np.ndarray | None = None):
    """``count`` evenly spread points on the mesh (head and hands denser), or on its faces ``where``.

    Returns points, normals, faces, spacing and (V, 24)-interpolated weights.
    """
    weight = _weighted_areas(mesh) * (1.0 if where is None else where)
    # systematic sampling along the faces' cumulative weight: every face gets its share in expectation,
    # small ones too (a largest-remainder split of counts below 1 would give them all to the largest
    # faces and leave the finely meshed nose and lips bare)
    cumulative = np.cumsum(weight)
    face = np.searchsorted(cumulative, (np.arange(count) + rng.random()) * (cumulative[-1] / count), side="right")
    face = np.minimum(face, len(weight) - 1)
    u, v = _plane_lattice(count, rng)  # consecutive points of R2 are far apart: a triangle's points spread
    root = np.sqrt(u)
    bary = np.column_stack([1.0 - root, root * (1.0 - v), root * v])
    corners = mesh.faces[face]
    points = np.einsum("nc,ncd->nd", bary, mesh.vertices[corners])
    normals = np.einsum("nc,ncd->nd", bary, mesh.normals[corners])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    weights = np.einsum("nc,ncj->nj", bary, mesh.weights[corners])
    density = _mesh_density(mesh)
    spacing = np.sqrt(float(weight.sum()) / count / density[face])
    return points, normals, face, spacing, weights


HAIR_THICKNESS_M = {"short": 0.008, "curly": 0.018, "bun": 0.006, "ponytail": 0.006}  # styles that hug the skull


def _scalp_hair(p: AvatarParams, mesh, hc: np.ndarray, hr: np.ndarray, count: int, rng: np.random.Generator):
    """``count`` points of hair lying on Anny's scalp, raised by the style's thickness along the normals.

    The styled region is :func:`_hair_mask` of each point's direction in the hair shell (the hairline,
    the open face); the head's own shape, not an ellipsoid, gives the hair its outline. Returns
    points, normals, the position along the part (0) and the shell directions, as :func:`_sample`.
    """
    head = mesh.face_region == "head"
    n = count
    while True:  # an even sample of the head large enough that its styled region holds ≥ count points
        pts, nrm, _, _, _ = _mesh_sample(mesh, n, rng, where=head)
        v = (pts - hc) / hr
        v /= np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
        kept = np.flatnonzero(_hair_styled(p, v))
        if len(kept) >= count:
            break
        n = int(np.ceil(n * max(1.05, 1.02 * count / max(len(kept), 1))))
    kept = np.sort(rng.choice(kept, count, replace=False))
    raised = pts[kept] + nrm[kept] * HAIR_THICKNESS_M[p.hair] * p.height_m / 1.75
    return raised, nrm[kept], np.zeros(count), v[kept]


def _anny_face(p: AvatarParams, points: np.ndarray, normals: np.ndarray, eyes: np.ndarray, mouth: np.ndarray):
    """Skin colours of a modelled face's front, in metres around its own eyes and mouth.

    The relief is the mesh's; what is painted is what a face's colour adds to it: the shadow of the eye
    sockets under the brow, an arched brow 2.2–2.6 cm over each eye, the upper lid's lash line, lips
    (the line between them darker), cheeks, and the sheen of forehead and cheekbones (stronger the
    darker the skin: on dark skin the highlights carry a face's form).
    """
    skin = np.array(p.skin)
    out = skin * (1.0 + 0.035 * np.sin(points[:, 0] * 23 + 1.3) * np.sin(points[:, 1] * 19))[:, None]
    centre = eyes.mean(axis=0)
    front = (points[:, 0] > centre[0] - 0.02) & (normals[:, 0] > 0.1)
    y, z = points[:, 1] - centre[1], points[:, 2] - centre[2]

    def bump(cy: float, cz: float, ry: float, rz: float) -> np.ndarray:
        return front * np.exp(-(((y - cy) / ry) ** 2 + ((z - cz) / rz) ** 2))

    half = float(eyes[0, 1] - centre[1])  # half the distance between the eyes
    sockets = bump(half, 0.002, 0.017, 0.011) + bump(-half, 0.002, 0.017, 0.011)
    out *= (1.0 - 0.18 * np.clip(sockets, 0.0, 1.0))[:, None] ** [0.85, 1.0, 1.05]  # warm shadow
    sheen = bump(0.0, 0.045, 0.035, 0.012) + bump(0.035, -0.022, 0.012, 0.008) + bump(-0.035, -0.022, 0.012, 0.008)
    out += (0.3 * np.clip(sheen, 0.0, 1.0))[:, None] * (1.0 - out) * (1.0 - np.mean(skin))
    brow = np.array(p.hair_colour) * 0.6 if np.mean(p.hair_colour) < 0.6 else skin * 0.55
    for side in (1.0, -1.0):
        across = (y - side * (half + 0.003)) / 0.014
        arch = 0.022 + 0.004 * (1.0 - np.clip(across, -1.0, 1.0) ** 2)
        out[front & (np.abs(across) < 1.0) & (np.abs(z - arch) < 0.0028)] = brow
        lid = front & (np.abs(y - side * half) < 0.012) & (z > 0.004) & (z < 0.0065)
        out[lid & (points[:, 0] > eyes[0, 0])] = [0.1, 0.07, 0.06]
        cheek = bump(side * 0.036, -0.03, 0.015, 0.012)
        out *= (1.0 - 0.05 * cheek)[:, None] * [1.0, 0.93, 0.93] + (0.05 * cheek)[:, None] * [1.0, 1.0, 1.0]
    my, mz = y, points[:, 2] - mouth[2]
    lips = (
        front
        & (np.abs(my) < 0.022 * np.sqrt(np.clip(1.0 - (mz / 0.009) ** 2, 0.0, 1.0)))
        & (mz > -0.009)
        & (mz < 0.006)
    )
    out[lips] = skin * [0.88, 0.64, 0.62]
    out[lips & (np.abs(mz) < 0.0012)] = skin * [0.55, 0.36, 0.35]
    return out


def _eye_colours(p: AvatarParams, points: np.ndarray, eyes: np.ndarray) -> np.ndarray:
    """An eyeball: sclera, an iris of the identity's colour within 30° of its front, a pupil within 12°."""
    out = np.tile([0.8, 0.77, 0.74], (len(points), 1))
    centre = np.where((points[:, 1] > eyes[:, 1].mean())[:, None], eyes[0], eyes[1])
    d = points - centre
    front = d[:, 0] / np.maximum(np.linalg.norm(d, axis=1), 1e-9)
    out[front > np.cos(np.radians(30.0))] = np.array(p.eye_colour) * 0.7
    out[front > np.cos(np.radians(12.0))] = [0.03, 0.03, 0.03]
    return out


def _mesh_colours(p: AvatarParams, mesh, rest: np.ndarray, points, normals, face, dominant) -> np.ndarray:
    """Per-point RGB on the Anny body: clothing, skin, shoes and face by the region each point skins to."""
    region = np.array([_MESH_REGION[JOINT_NAMES[j]] for j in range(N_JOINTS)])[dominant]
    # the neckline: a crew neck, lower in front, whatever joint the points near it skin to
    s = p.height_m / 1.75
    neck = rest[J["neck"]]
    line = neck[2] + 0.005 * s - 0.3 * np.clip(points[:, 0] - neck[0], 0.0, None) + 0.5 * np.abs(points[:, 1])
    upper = np.isin(region, ("torso", "neck"))
    region[upper] = np.where(points[upper, 2] < line[upper], "torso", "neck")
    region[mesh.face_region[face] == "eye"] = "eye"
    colours = np.zeros_like(points)
    for name in np.unique(region):
        sel = region == name
        pts, nrm = points[sel], normals[sel]
        if name == "eye":
            colours[sel] = _eye_colours(p, pts, mesh.eyes)
            continue
        if name in _MESH_BONE:
            a, b = (rest[J[joint]] for joint in _MESH_BONE[name])
            axis = b - a
            length = float(np.linalg.norm(axis))
            width, depth = _frame(axis / length)
            rel = pts - a
            t = np.clip(rel @ axis / length**2, 0.0, 1.0)  # a limb's region runs a little past its joints
            angle = np.arctan2(rel @ depth, rel @ width)
            v = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(len(pts))])
        elif name == "head":
            colours[sel] = _anny_face(p, pts, nrm, mesh.eyes, mesh.mouth)
            continue
        else:
            t, v = np.zeros(len(pts)), np.zeros_like(pts)
        colours[sel] = _colours(p, _Part(name, pts[0], None, (1.0, 1.0, 1.0), name), pts, nrm, t, v)
    return colours


def _head_shell(mesh, s: float) -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid around Anny's skull (the hair's shell): back of the head, forehead, crown, temples."""
    head = np.unique(mesh.faces[mesh.face_region == "head"])
    eye_z = float(mesh.eyes[:, 2].mean())
    skull = mesh.vertices[head]
    skull = skull[skull[:, 2] > eye_z - 0.01 * s]
    back = float(skull[:, 0].min())
    front = float(skull[skull[:, 2] > eye_z + 0.03 * s, 0].max())
    top = float(skull[:, 2].max())
    centre = np.array([0.5 * (back + front), 0.0, eye_z + 0.01 * s])
    radii = np.array([0.5 * (front - back), float(np.abs(skull[:, 1]).max()), top - centre[2]])
    return centre, radii


def _anny_surfels(p: AvatarParams, rest: np.ndarray, n: int, rng: np.random.Generator) -> _Surfels:
    """Anny's body with the procedural clothing painted on it, and hair, skirt and kit as layers over it."""
    from song.datasets.avatars import body_model

    values = body_model.phenotype(p.sex, p.age_years, _anny_z(p))
    mesh = body_model.anny_body(p.height_m, values)
    s = p.height_m / 1.75
    hc, hr = _head_shell(mesh, s)
    dominant_v = mesh.weights.argmax(axis=1)
    hip_band = np.abs(mesh.vertices[:, 2] - (rest[J["pelvis"], 2] + 0.03 * s)) < 0.02 * s
    waist_half = float(np.abs(mesh.vertices[hip_band, 1]).max())
    layers = _layer_parts(p, rest, hc, hr, waist_half / p.girth, eyes=mesh.eyes)
    layer_area = np.array([_area(part) for part in layers])
    counts = _split(np.concatenate([[float(_weighted_areas(mesh).sum())], layer_area * [q.density for q in layers]]), n)
    points, normals, face, spacing, dense = _mesh_sample(mesh, int(counts[0]), rng)
    dominant = dense.argmax(axis=1)
    colours = _mesh_colours(p, mesh, rest, points, normals, face, dominant)

    def sample(part: _Part, count: int):
        if part.name == "hair" and p.hair in HAIR_THICKNESS_M:
            return _scalp_hair(p, mesh, hc, hr, count, rng)
        return _sample_part(p, part, count, rng)

    body = (points, normals, colours, spacing, np.zeros(len(points), bool), np.full(len(points), "body"))
    layered = _part_surfels(p, layers, counts[1:], layer_area, sample)
    means, nrm, cols, spc, hanging, regions = (np.concatenate([x, y]) for x, y in zip(body, layered, strict=True))
    _layer_colours(p, layers, regions, means, cols)
    indices, weights = top_k(np.vstack([dense, np.zeros((len(means) - len(points), N_JOINTS))]))
    layered = np.arange(len(means)) >= len(points)
    if layered.any():  # hair, glasses, a skirt or a bag: by bone distance, then what hangs follows the hips
        indices[layered], weights[layered] = transfer_weights(means[layered], rest, p.height_m)
    _hang_from_pelvis(p, rest, means, hanging, indices, weights)
    radius = _mesh_body_radius(mesh, rest, dominant_v)
    extra = {"anny": {"version": body_model.ANNY_VERSION, **{k: round(v, 4) for k, v in values.items()}}}
    return _Surfels(means, nrm, cols, spc, indices, weights, radius, extra)


def _mesh_body_radius(mesh, rest: np.ndarray, dominant: np.ndarray) -> float:
    """Half the larger of the bideltoid breadth and the hip breadth + 4 cm, measured on the body.

    The bideltoid breadth is taken with the arms hanging: twice the shoulder joint's offset plus the
    upper arm's median radius around its bone.
    """
    z = mesh.vertices[:, 2]
    h = float(z.max())
    legs = (z > 0.45 * h) & (z < 0.55 * h)
    hip = 2.0 * float(np.abs(mesh.vertices[legs, 1]).max())
    radii = []
    for side in ("left", "right"):
        sel = dominant == J[f"{side}_shoulder"]
        a, b = rest[J[f"{side}_shoulder"]], rest[J[f"{side}_elbow"]]
        axis = (b - a) / np.linalg.norm(b - a)
        rel = mesh.vertices[sel] - a
        radii.append(float(np.median(np.linalg.norm(rel - (rel @ axis)[:, None] * axis, axis=1))))
    bideltoid = 2.0 * (abs(float(rest[J["left_shoulder"], 1])) + float(np.mean(radii)))
    return round(0.5 * max(bideltoid, hip + 0.04), 4)


BODIES = ("anny", "procedural")


def default_body() -> str:
    """``anny`` where it is installed (``pip install song[avatars]``), else ``procedural``."""
    from song.datasets.avatars import body_model

    return "anny" if body_model.available() else "procedural"


def generate_avatar(
    rng: np.random.Generator,
    avatar_id: str,
    n_gaussians: int = 40_000,
    params: AvatarParams | None = None,
    body: str | None = None,
) -> AvatarAsset:
    """One identity with exactly ``n_gaussians`` Gaussians (5,000–100,000).

    ``body`` is ``anny`` (the parametric body model), ``procedural`` (surfaces around the bones) or None
    (:func:`default_body`).
    """
    if not 5_000 <= n_gaussians <= 100_000:
        raise ValueError(f"n_gaussians={n_gaussians}: expected 5,000–100,000")
    body = body or default_body()
    if body not in BODIES:
        raise ValueError(f"body={body!r}: expected one of {BODIES}")
    if body == "anny":
        from song.datasets.avatars.body_model import available

        if not available():
            raise ValueError(
                "body='anny': Anny is not installed (pip install 'song[avatars]'), or use body='procedural'"
            )
    p = params or sample_params(rng)
    rest = rest_joints(p.height_m)
    made = (_anny_surfels if body == "anny" else _procedural_surfels)(p, rest, n_gaussians, rng)
    colours = _shade(made.colours, made.normals, made.means, p.height_m)
    colours = np.clip(colours * rng.uniform(0.975, 1.025, (len(colours), 1)), 0.0, 1.0)  # fine grain
    spacing = made.spacing
    log_scales = np.log(np.column_stack([0.75 * spacing, 0.75 * spacing, 0.12 * spacing]))
    cloud = GaussianCloud(
        means=made.means.astype(np.float32),
        quats=_disc_quats(made.normals).astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        opacity_logits=np.full(n_gaussians, 4.0, np.float32),
        sh_dc=((colours - 0.5) / SH_C0).astype(np.float32),
    )
    meta = {
        "source": "procedural",
        "height_m": float(p.height_m),
        "scale": 1.0,
        "body_radius_m": made.body_radius_m,
        "generator": {
            "name": "song.datasets.avatars.generate",
            "version": GENERATOR_VERSION,
            "body": body,
            **vars(p),
            **made.extra,
        },
    }
    return AvatarAsset(avatar_id, cloud, made.indices, made.weights, rest.astype(np.float32), meta)


def build_pool(
    out_dir: str | Path, count: int, seed: int, n_gaussians: int = 40_000, body: str | None = None
) -> list[Path]:
    """Write ``count`` identities ``avatar_{seed}_{i:04d}.avatar.npz``; avatar i depends only on (seed, i, body)."""
    paths = []
    for index in range(count):
        rng = derive_rng(seed, "avatar", index)
        asset = generate_avatar(rng, f"avatar_{seed}_{index:04d}", n_gaussians, body=body)
        asset.meta["generator"].update(seed=seed, index=index)
        paths.append(save_avatar(asset, out_dir))
    return paths
