"""Furniture shapes by category: a scene object's footprint and height → solid parts (boxes, cylinders, ellipsoids).

Each object becomes a few parts inside its footprint's minimum rotated rectangle (local x along the
long side, local y toward the room: the side of the rectangle away from the nearest wall is the
front): tables get a top and four legs, desks and workstations a monitor too, counters a body and an
overhanging top, shelves a frame, boards and items, beds a base, a mattress, a headboard and pillows,
sofas a seat, a back and arms, chairs a seat, a back and legs, plants a pot and foliage, appliances a
body with a front panel, fixtures (toilets, sinks, baths) ceramic shapes; anything else is a box.
Every part stays inside the footprint, so the occupancy map (which rasterises the footprint) covers it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from song.util import derive_rng

FACES = ("top", "bottom", "+x", "-x", "+y", "-y")


@dataclass(frozen=True)
class Part:
    """One solid piece of a scene.

    Attributes:
        name: a stable name (``"desk_1/top"``), also the USD prim name.
        group: what it belongs to: an object id, ``"lintel"``, ``"frame"``, ``"door"`` (an entrance's closed door).
        kind: ``"box"`` (oriented box), ``"cylinder"`` (upright, elliptic section) or ``"ellipsoid"``.
        centre: (x, y) of the part's axis, m.
        yaw: rotation of the local x axis from world +x, rad.
        half: half sizes along local x and y (radii for cylinders and ellipsoids), m.
        z0: bottom, m. z1: top, m.
        material: a key of :data:`song.datasets.scenes.materials.MATERIALS`.
        hidden: faces not emitted as Gaussians (``"bottom"`` of things on the floor, ``"+y"`` of open shelves).
    """

    name: str
    group: str
    kind: str
    centre: tuple[float, float]
    yaw: float
    half: tuple[float, float]
    z0: float
    z1: float
    material: str
    hidden: tuple[str, ...] = ()


@dataclass(frozen=True)
class Frame:
    """An object's oriented rectangle: centre (2,), unit axes ``ax`` (long, local x) and ``ay`` (front), half sizes."""

    centre: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    hx: float
    hy: float

    @property
    def yaw(self) -> float:
        """Yaw of the local x axis, rad."""
        return math.atan2(self.ax[1], self.ax[0])

    def at(self, x: float, y: float) -> tuple[float, float]:
        """World (x, y) of local coordinates (m from the centre)."""
        p = self.centre + x * self.ax + y * self.ay
        return float(p[0]), float(p[1])


def object_frame(footprint: np.ndarray, wall_side: float) -> Frame:
    """The footprint's minimum rotated rectangle with local y pointing away from the wall side.

    Args:
        footprint: (K, 2) CCW polygon, m.
        wall_side: clearance difference ``clearance(front) − clearance(back)`` sign convention: the
            caller passes +1 when the rectangle's +y side has more free space than its −y side.
    """
    from shapely.geometry import Polygon

    rect = np.asarray(Polygon(footprint).minimum_rotated_rectangle.exterior.coords)[:4]
    e1, e2 = rect[1] - rect[0], rect[2] - rect[1]
    if np.linalg.norm(e2) > np.linalg.norm(e1):
        e1, e2 = e2, e1
    hx, hy = np.linalg.norm(e1) / 2, np.linalg.norm(e2) / 2
    ax = e1 / max(2 * hx, 1e-9)
    ay = np.array([-ax[1], ax[0]])
    if wall_side < 0:
        ax, ay = -ax, -ay
    return Frame(rect.mean(axis=0), ax, ay, float(hx), float(hy))


def _box(name, group, frame: Frame, x, y, hx, hy, z0, z1, material, hidden=()) -> Part:
    return Part(name, group, "box", frame.at(x, y), frame.yaw, (hx, hy), z0, z1, material, hidden)


def _floor_box(name, group, frame: Frame, x, y, hx, hy, z1, material, hidden=()) -> Part:
    return _box(name, group, frame, x, y, hx, hy, 0.0, z1, material, ("bottom", *hidden))


def _pick(rng: np.random.Generator, options: tuple[str, ...]) -> str:
    return options[int(rng.integers(len(options)))]


def _legs(oid: str, f: Frame, height: float, material: str, inset: float = 0.04, size: float = 0.025) -> list[Part]:
    hx, hy = max(f.hx - inset - size, size), max(f.hy - inset - size, size)
    return [
        _floor_box(f"{oid}/leg{k}", oid, f, sx * hx, sy * hy, size, size, height, material)
        for k, (sx, sy) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1)))
    ]


def table(oid: str, f: Frame, height: float, rng, desk: bool = False) -> list[Part]:
    """A top slab on four legs (desks and workstations: with a monitor and a keyboard)."""
    wood = _pick(rng, ("wood_light", "wood_medium", "wood_dark", "metal_white"))
    top = 0.035
    parts = [_box(f"{oid}/top", oid, f, 0, 0, f.hx, f.hy, height - top, height, wood)]
    parts += _legs(oid, f, height - top, "metal_dark" if desk else wood)
    if desk and f.hy > 0.2 and f.hx > 0.3:
        w = min(0.28, f.hx * 0.6)
        parts.append(_box(f"{oid}/monitor", oid, f, 0, -f.hy + 0.12, w, 0.025, height + 0.12, height + 0.48, "screen"))
        parts.append(_box(f"{oid}/stand", oid, f, 0, -f.hy + 0.15, 0.03, 0.03, height, height + 0.12, "plastic_black"))
        parts.append(
            _box(
                f"{oid}/keyboard",
                oid,
                f,
                0,
                -f.hy + 0.38,
                min(0.22, f.hx * 0.5),
                0.07,
                height,
                height + 0.02,
                "plastic_black",
            )
        )
    return parts


def counter(oid: str, f: Frame, height: float, rng, kitchen: bool) -> list[Part]:
    """A solid body with an overhanging top."""
    body = _pick(rng, ("wood_light", "wood_medium", "metal_white") if not kitchen else ("metal_white", "wood_light"))
    top = "stone" if kitchen else _pick(rng, ("wood_dark", "stone"))
    return [
        _floor_box(f"{oid}/body", oid, f, 0, -0.02, f.hx - 0.02, f.hy - 0.02, height - 0.04, body),
        _box(f"{oid}/top", oid, f, 0, 0, f.hx, f.hy, height - 0.04, height, top),
    ]


def shelf(oid: str, f: Frame, height: float, rng, books: bool) -> list[Part]:
    """An open shelving unit: back, sides, top, boards every ~0.38 m and items on each board."""
    wood = _pick(rng, ("wood_light", "wood_medium", "metal_steel"))
    t = 0.02
    parts = [
        _floor_box(f"{oid}/back", oid, f, 0, -f.hy + t, f.hx, t, height, wood),
        _floor_box(f"{oid}/left", oid, f, -f.hx + t, 0, t, f.hy, height, wood),
        _floor_box(f"{oid}/right", oid, f, f.hx - t, 0, t, f.hy, height, wood),
        _box(f"{oid}/roof", oid, f, 0, 0, f.hx, f.hy, height - t, height, wood),
    ]
    n_boards = max(1, int(height / 0.38))
    inner_x, inner_y = f.hx - 2 * t, f.hy - 2 * t
    for k in range(n_boards):
        z = 0.08 + k * (height - 0.1) / n_boards
        parts.append(_box(f"{oid}/board{k}", oid, f, 0, t, inner_x, inner_y, z, z + t, wood))
        if inner_y > 0.05 and z + 0.3 < height:
            fill = 0.7 + 0.25 * rng.random()
            item_h = min(0.28, (height - 0.1) / n_boards - 0.05) * (0.7 + 0.3 * rng.random())
            material = "books" if books else _pick(rng, ("fabric_red", "fabric_blue", "metal_white", "fabric_beige"))
            parts.append(
                _box(
                    f"{oid}/items{k}", oid, f, 0, -0.02, inner_x * fill, inner_y * 0.8, z + t, z + t + item_h, material
                )
            )
    return parts


def cabinet(oid: str, f: Frame, height: float, rng, material: str | None = None) -> list[Part]:
    """A closed box with a front panel (wardrobes, dressers, stands, appliances, elevators)."""
    body = material or _pick(rng, ("wood_light", "wood_medium", "wood_dark"))
    panel = "metal_dark" if body.startswith("metal") else "wood_dark"
    parts = [_floor_box(f"{oid}/body", oid, f, 0, -0.01, f.hx, f.hy - 0.01, height, body)]
    if f.hx > 0.15:
        parts.append(_box(f"{oid}/panel", oid, f, 0, f.hy - 0.01, f.hx * 0.9, 0.01, height * 0.1, height * 0.92, panel))
    return parts


def bed(oid: str, f: Frame, height: float, rng) -> list[Part]:
    """Base, mattress, headboard at one short end, pillows, a blanket."""
    frame_wood = _pick(rng, ("wood_light", "wood_medium", "wood_dark"))
    top = min(height, 0.55)
    head = max(height, 0.95)
    blanket = _pick(rng, ("fabric_blue", "fabric_grey", "fabric_beige", "fabric_green"))
    return [
        _floor_box(f"{oid}/base", oid, f, 0, 0, f.hx, f.hy, 0.3, frame_wood),
        _box(f"{oid}/mattress", oid, f, 0.04, 0, f.hx - 0.06, f.hy - 0.02, 0.3, top - 0.04, "linen_white"),
        _box(f"{oid}/blanket", oid, f, 0.2, 0, f.hx - 0.24, f.hy - 0.01, top - 0.06, top, blanket),
        _floor_box(f"{oid}/head", oid, f, -f.hx + 0.04, 0, 0.04, f.hy, head, frame_wood),
        _box(f"{oid}/pillow", oid, f, -f.hx + 0.25, 0, 0.16, f.hy * 0.8, top - 0.04, top + 0.1, "linen_white"),
    ]


def sofa(oid: str, f: Frame, height: float, rng, arms: bool = True) -> list[Part]:
    """Seat, back along the back side, arms at the short ends."""
    fabric = _pick(rng, ("fabric_grey", "fabric_blue", "fabric_green", "fabric_beige", "fabric_red"))
    back = min(0.2, f.hy * 0.4)
    arm = min(0.15, f.hx * 0.2) if arms else 0.0
    parts = [  # the seat stops at the arms: coplanar end faces would fight in a renderer
        _floor_box(f"{oid}/seat", oid, f, 0, back / 2, f.hx - arm, f.hy - back / 2, min(0.44, height), fabric),
        _floor_box(f"{oid}/back", oid, f, 0, -f.hy + back / 2, f.hx, back / 2, height, fabric),
    ]
    if arm:
        for k, sx in enumerate((-1, 1)):
            parts.append(
                _floor_box(
                    f"{oid}/arm{k}",
                    oid,
                    f,
                    sx * (f.hx - arm / 2),
                    back / 2,
                    arm / 2,
                    f.hy - back / 2,
                    min(0.62, height),
                    fabric,
                )
            )
    return parts


def chair(oid: str, f: Frame, height: float, rng, name: str = "") -> list[Part]:
    """Seat on four legs with a back."""
    frame_material = _pick(rng, ("metal_dark", "wood_medium", "metal_steel"))
    seat_material = _pick(rng, ("fabric_blue", "fabric_grey", "plastic_black", "wood_light"))
    seat = min(0.46, height * 0.6)
    return [
        _box(f"{oid}{name}/seat", oid, f, 0, 0, f.hx, f.hy, seat - 0.05, seat, seat_material),
        _box(f"{oid}{name}/back", oid, f, 0, -f.hy + 0.03, f.hx, 0.03, seat, height, seat_material),
        *_legs(f"{oid}{name}", f, seat - 0.05, frame_material, inset=0.02, size=0.02),
    ]


def chair_row(oid: str, f: Frame, height: float, rng) -> list[Part]:
    """A row of chairs along the long side (waiting chairs)."""
    n = max(1, int(round(2 * f.hx / 0.55)))
    width = 2 * f.hx / n
    parts = []
    for k in range(n):
        centre = f.centre + (-f.hx + (k + 0.5) * width) * f.ax
        sub = Frame(centre, f.ax, f.ay, width / 2 - 0.02, f.hy)
        parts += chair(oid, sub, height, rng, name=f"/chair{k}")
    return parts


def plant(oid: str, f: Frame, height: float, rng) -> list[Part]:
    """A clay pot and an ellipsoid of foliage."""
    r = min(f.hx, f.hy)
    pot_top = min(0.4, 0.35 * height)
    cx, cy = f.at(0, 0)
    return [
        Part(f"{oid}/pot", oid, "cylinder", (cx, cy), 0.0, (0.7 * r, 0.7 * r), 0.0, pot_top, "pot_clay", ("bottom",)),
        Part(f"{oid}/leaves", oid, "ellipsoid", (cx, cy), 0.0, (r, r), pot_top * 0.8, height, "foliage"),
    ]


def fixture(oid: str, f: Frame, height: float, rng, label: str) -> list[Part]:
    """Bathroom fixtures in white ceramic."""
    if "toilet" in label:
        return [
            _floor_box(f"{oid}/bowl", oid, f, 0, 0.05, f.hx * 0.8, f.hy - 0.05, min(0.42, height), "ceramic_white"),
            _floor_box(f"{oid}/tank", oid, f, 0, -f.hy + 0.09, f.hx, 0.09, height, "ceramic_white"),
        ]
    if "sink" in label:
        return [
            _floor_box(f"{oid}/cabinet", oid, f, 0, 0, f.hx, f.hy, height - 0.1, "wood_light"),
            _box(f"{oid}/basin", oid, f, 0, 0, f.hx, f.hy, height - 0.1, height, "ceramic_white"),
        ]
    return [_floor_box(f"{oid}/body", oid, f, 0, 0, f.hx, f.hy, height, "ceramic_white")]


def object_parts(oid: str, label: str, category: str, frame: Frame, height: float, venue: str, seed: int) -> list[Part]:
    """The parts of one scene object (see the module docstring); [] for doors and entrances."""
    rng = derive_rng(seed, "furniture", oid)
    label = label.lower()
    height = max(float(height), 0.05)
    if category in ("entrance", "door") or "door" in label:
        return []
    if "waiting chair" in label:
        return chair_row(oid, frame, height, rng)
    if "chair" in label and "arm" not in label:
        return chair(oid, frame, height, rng)
    if any(k in label for k in ("desk", "workstation")) and "reception" not in label and "help" not in label:
        return table(oid, frame, height, rng, desk=True)
    if category == "table" or "table" in label:
        return table(oid, frame, height, rng)
    if category in ("counter", "reception") or any(k in label for k in ("counter", "checkout", "bar")):
        return counter(oid, frame, height, rng, kitchen="kitchen" in label or "counter top" in label)
    if any(k in label for k in ("shelf", "shelving", "book", "stack")):
        return shelf(oid, frame, height, rng, books=venue == "library" or "book" in label)
    if "bed" in label and "examination" not in label:
        return bed(oid, frame, height, rng)
    if "examination" in label:
        return [_floor_box(f"{oid}/base", oid, frame, 0, 0, frame.hx, frame.hy, height - 0.08, "metal_steel"),
                _box(f"{oid}/pad", oid, frame, 0, 0, frame.hx, frame.hy, height - 0.08, height, "fabric_blue")]  # fmt: skip
    if any(k in label for k in ("sofa", "couch", "arm chair", "armchair")):
        return sofa(oid, frame, height, rng)
    if any(k in label for k in ("plant", "tree")):
        return plant(oid, frame, height, rng)
    if category == "fixture" or any(k in label for k in ("toilet", "sink", "bathtub")):
        return fixture(oid, frame, height, rng, label)
    if category in ("appliance", "equipment", "transport") or any(
        k in label for k in ("fridge", "printer", "machine", "microwave", "elevator", "television", "tv")
    ):
        material = "metal_steel" if "elevator" in label else _pick(rng, ("metal_white", "metal_steel", "metal_dark"))
        return cabinet(oid, frame, height, rng, material)
    if category == "storage" or any(k in label for k in ("wardrobe", "dresser", "stand", "rack", "cabinet")):
        return cabinet(oid, frame, height, rng)
    return [
        _floor_box(
            f"{oid}/body",
            oid,
            frame,
            0,
            0,
            frame.hx,
            frame.hy,
            height,
            _pick(rng, ("wood_medium", "metal_steel", "fabric_grey")),
        )
    ]
