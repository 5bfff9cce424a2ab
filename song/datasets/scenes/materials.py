"""Surface materials of synthesised scenes: base colours and procedural textures (deterministic).

A material is a base colour plus a texture kind evaluated on surface coordinates (u, v) in metres:

- ``plaster``: painted walls and ceilings, a faint low-frequency mottling;
- ``wood``: grain along u (boards 12–20 cm wide, each with its own tone), used for floors and furniture;
- ``tiles``: square tiles with darker grout lines and a per-tile tone;
- ``carpet``: fine speckle over a low-frequency variation;
- ``fabric``: a weave pattern with soft noise (sofas, beds, chairs);
- ``metal``: near-uniform with a slight gradient (appliances, elevators, frames);
- ``foliage``: greens with strong per-point variation (plants).

Noise is hashed value noise on an integer lattice, seeded, so the same scene and seed give the same
colours. Colours are linear-ish sRGB in [0, 1].

**Instances differ.** ``"<material>~k"`` (k < :data:`VARIANTS`) is variant k of a material: its base
colour brighter or darker by up to 12 % and warmer or cooler by up to 3 %, its pattern drawn at
0.8–1.25 times the size (tiles, boards) and from its own noise seed. The scene synthesis gives every
object instance the variant its id hashes to, so the chairs of a room are not one colour and one
grain, the way real furniture of one kind differs by batch, wear and light history.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Material:
    """A base colour (3,) in [0, 1], a texture kind (see the module docstring) and its pattern's scale."""

    name: str
    base: tuple[float, float, float]
    texture: str
    scale: float = 1.0  # tile and board sizes are multiplied by this


MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("plaster_white", (0.90, 0.89, 0.86), "plaster"),
        Material("plaster_warm", (0.89, 0.84, 0.75), "plaster"),
        Material("plaster_cool", (0.80, 0.85, 0.88), "plaster"),
        Material("plaster_green", (0.76, 0.84, 0.77), "plaster"),
        Material("plaster_grey", (0.74, 0.74, 0.73), "plaster"),
        Material("ceiling", (0.95, 0.95, 0.94), "plaster"),
        Material("wood_light", (0.74, 0.58, 0.40), "wood"),
        Material("wood_medium", (0.56, 0.38, 0.22), "wood"),
        Material("wood_dark", (0.36, 0.24, 0.15), "wood"),
        Material("tiles_light", (0.86, 0.85, 0.82), "tiles"),
        Material("tiles_grey", (0.62, 0.63, 0.64), "tiles"),
        Material("tiles_terracotta", (0.70, 0.45, 0.33), "tiles"),
        Material("carpet_blue", (0.33, 0.38, 0.48), "carpet"),
        Material("carpet_grey", (0.48, 0.48, 0.47), "carpet"),
        Material("carpet_red", (0.52, 0.24, 0.22), "carpet"),
        Material("fabric_grey", (0.50, 0.51, 0.54), "fabric"),
        Material("fabric_blue", (0.28, 0.36, 0.55), "fabric"),
        Material("fabric_green", (0.33, 0.47, 0.36), "fabric"),
        Material("fabric_beige", (0.78, 0.71, 0.60), "fabric"),
        Material("fabric_red", (0.62, 0.22, 0.20), "fabric"),
        Material("linen_white", (0.93, 0.93, 0.90), "fabric"),
        Material("metal_steel", (0.70, 0.71, 0.73), "metal"),
        Material("metal_dark", (0.20, 0.21, 0.23), "metal"),
        Material("metal_white", (0.92, 0.92, 0.92), "metal"),
        Material("plastic_black", (0.08, 0.08, 0.09), "metal"),
        Material("screen", (0.05, 0.07, 0.10), "metal"),
        Material("ceramic_white", (0.95, 0.95, 0.96), "metal"),
        Material("foliage", (0.22, 0.45, 0.20), "foliage"),
        Material("pot_clay", (0.62, 0.36, 0.24), "tiles"),
        Material("books", (0.50, 0.30, 0.25), "books"),
        Material("stone", (0.66, 0.64, 0.60), "tiles"),
        Material("door_panel", (0.46, 0.33, 0.22), "wood"),
        Material("paper", (0.93, 0.93, 0.90), "fabric"),
        Material("cardboard", (0.64, 0.50, 0.34), "fabric"),
        Material("canvas_ochre", (0.78, 0.62, 0.32), "fabric"),
        Material("canvas_teal", (0.24, 0.48, 0.50), "fabric"),
        Material("canvas_rose", (0.76, 0.47, 0.47), "fabric"),
        Material("canvas_sky", (0.55, 0.68, 0.82), "fabric"),
        Material("sign_green", (0.10, 0.48, 0.26), "metal"),
        Material("sign_blue", (0.14, 0.30, 0.58), "metal"),
    )
}

# floor and wall defaults by region type, then by venue (first match wins)
FLOOR_BY_REGION = {
    "kitchen": "tiles_light",
    "kitchenette": "tiles_light",
    "bathroom": "tiles_light",
    "corridor": "tiles_grey",
    "reception": "stone",
    "lobby": "stone",
    "bedroom": "wood_light",
    "living_room": "wood_medium",
    "open_office": "carpet_grey",
    "office": "carpet_blue",
    "meeting_room": "carpet_blue",
    "consultation_room": "tiles_light",
    "pharmacy": "tiles_light",
    "waiting_area": "tiles_grey",
    "dining_room": "wood_medium",
    "bar": "wood_dark",
    "stacks": "carpet_red",
    "reading_room": "carpet_red",
}
FLOOR_BY_VENUE = {
    "office": "carpet_grey",
    "clinic": "tiles_light",
    "lobby": "stone",
    "shop": "tiles_grey",
    "restaurant": "wood_medium",
    "home": "wood_light",
    "library": "carpet_red",
}
WALL_BY_VENUE = {
    "office": "plaster_white",
    "clinic": "plaster_cool",
    "lobby": "plaster_warm",
    "shop": "plaster_white",
    "restaurant": "plaster_warm",
    "home": "plaster_warm",
    "library": "plaster_green",
}


def floor_material(region_type: str | None, venue: str) -> str:
    """The floor material of a region (by its type, else the venue's)."""
    return FLOOR_BY_REGION.get(region_type or "", FLOOR_BY_VENUE.get(venue, "tiles_grey"))


def wall_material(venue: str) -> str:
    """The wall paint of a venue."""
    return WALL_BY_VENUE.get(venue, "plaster_white")


def procthor_floor_material(name: str) -> str:
    """One of our floor materials for a ProcTHOR floor material name (by its family)."""
    low = name.lower()
    if "wood" in low or "parquet" in low or "laminate" in low:
        return "wood_medium" if "dark" not in low else "wood_dark"
    if "carpet" in low or "rug" in low:
        return "carpet_grey"
    if "tile" in low or "marble" in low or "ceramic" in low or "stone" in low or "concrete" in low:
        return "tiles_light" if "white" in low or "marble" in low else "tiles_grey"
    return "tiles_grey"


def _hash(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """Deterministic pseudo-random values in [0, 1) per integer lattice point (vectorised)."""
    h = (ix.astype(np.int64) * 374761393 + iy.astype(np.int64) * 668265263 + seed * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF).astype(np.float64) / float(0x1000000)


def value_noise(u: np.ndarray, v: np.ndarray, scale: float, seed: int) -> np.ndarray:
    """Smooth value noise in [0, 1) at coordinates (m) with features ``scale`` metres apart."""
    x, y = u / scale, v / scale
    ix, iy = np.floor(x), np.floor(y)
    fx, fy = x - ix, y - iy
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a, b = _hash(ix, iy, seed), _hash(ix + 1, iy, seed)
    c, d = _hash(ix, iy + 1, seed), _hash(ix + 1, iy + 1, seed)
    return (a * (1 - sx) + b * sx) * (1 - sy) + (c * (1 - sx) + d * sx) * sy


def srgb_to_linear(c: np.ndarray | float) -> np.ndarray:
    """sRGB-encoded values in [0, 1] → linear light (IEC 61966-2-1)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray | float) -> np.ndarray:
    """Linear light in [0, 1] → sRGB-encoded values (IEC 61966-2-1)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(np.maximum(c, 0.0), 1 / 2.4) - 0.055)


VARIANTS = 5  # variants per material (instances pick one by their id)
_BRIGHTNESS = (1.0, 1.06, 0.94, 1.12, 0.88)  # variant 0 is the material as listed
_WARMTH = (0.0, -0.02, 0.03, 0.01, -0.03)  # + warmer (more red, less blue), − cooler
_SCALE = (1.0, 1.25, 0.8, 1.1, 0.9)


def variant(name: str, k: int) -> str:
    """The name of variant ``k`` of material ``name`` (``"wood_medium~3"``)."""
    return f"{name}~{k % VARIANTS}"


def material_of(name: str) -> Material:
    """A material by name; ``"paint:#rrggbb"`` is a plaster wall of that colour, ``"name~k"`` a variant."""
    if "~" in name:
        root, k = name.rsplit("~", 1)
        m, k = material_of(root), int(k) % VARIANTS
        warm = np.array([1 + _WARMTH[k], 1.0, 1 - _WARMTH[k]])
        base = np.clip(np.asarray(m.base) * _BRIGHTNESS[k] * warm, 0.0, 1.0)
        return Material(name, tuple(float(c) for c in base), m.texture, m.scale * _SCALE[k])
    if name.startswith("paint:#") and len(name) == 13:
        rgb = tuple(int(name[7 + 2 * k : 9 + 2 * k], 16) / 255.0 for k in range(3))
        return Material(name, rgb, "plaster")
    return MATERIALS[name]


def texture(material: str, u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    """(N, 3) colours of ``material`` at surface coordinates (u, v), metres."""
    m = material_of(material)
    base = np.asarray(m.base, dtype=np.float64)
    n = len(u)
    if m.texture == "plaster":
        tone = 1.0 + 0.05 * (value_noise(u, v, 0.8, seed) - 0.5) + 0.02 * (value_noise(u, v, 0.05, seed + 1) - 0.5)
        return base * tone[:, None]
    u, v = u / m.scale, v / m.scale  # the pattern at its size
    if m.texture == "wood":
        board = np.floor(v / 0.16)
        tone = 0.85 + 0.3 * _hash(board, board * 7 + 3, seed)
        grain = 0.06 * np.sin(2 * np.pi * (u / 0.9 + 3.0 * value_noise(u, v * 8, 0.5, seed + 2)))
        seam = np.where(np.abs(v / 0.16 - np.round(v / 0.16)) < 0.04, 0.8, 1.0)
        return base * ((tone + grain) * seam)[:, None]
    if m.texture == "tiles":
        size = 0.45
        fu, fv = u / size - np.floor(u / size), v / size - np.floor(v / size)
        grout = (np.minimum(fu, 1 - fu) < 0.025) | (np.minimum(fv, 1 - fv) < 0.025)
        tone = 0.93 + 0.14 * _hash(np.floor(u / size), np.floor(v / size), seed)
        colour = base * tone[:, None]
        colour[grout] = base * 0.62
        return colour
    if m.texture == "carpet":
        tone = (
            0.9
            + 0.12 * value_noise(u, v, 0.6, seed)
            + 0.1 * (_hash(np.floor(u / 0.01), np.floor(v / 0.01), seed) - 0.5)
        )
        return base * tone[:, None]
    if m.texture == "fabric":
        weave = 0.04 * np.sin(2 * np.pi * u / 0.02) * np.sin(2 * np.pi * v / 0.02)
        tone = 0.92 + 0.1 * value_noise(u, v, 0.3, seed) + weave
        return base * tone[:, None]
    if m.texture == "metal":
        tone = 0.95 + 0.08 * value_noise(u, v, 1.5, seed)
        return base * tone[:, None]
    if m.texture == "foliage":
        tone = 0.6 + 0.8 * _hash(np.floor(u / 0.04), np.floor(v / 0.04), seed)
        return base * tone[:, None]
    if m.texture == "books":  # spines: a colour per 3–5 cm book
        spine = np.floor(u / 0.04)
        palette = np.array(
            [[0.55, 0.15, 0.12], [0.15, 0.25, 0.45], [0.20, 0.40, 0.25], [0.75, 0.65, 0.40], [0.30, 0.30, 0.32]]
        )
        pick = (_hash(spine, spine * 3 + 1, seed) * len(palette)).astype(np.int64)
        return palette[pick] * (0.85 + 0.3 * _hash(spine, spine + 11, seed))[:, None]
    return np.tile(base, (n, 1))
