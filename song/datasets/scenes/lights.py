"""A scene's light sources: ceiling lights per room, lamps, windows with daylight, and its exposure.

``lights.json`` (format ``song.lights``, version 1) in a scene package lists them; ``song scenes splat``
writes it when the package has none (placed by the rules below) and never overwrites it, so a user can
edit it and re-bake with ``song scenes light``. The USD proxy carries the same lights as ``UsdLux``
prims under ``/World/lights`` for simulators.

Two kinds, in the radiometric conventions of Blender Cycles (the reference renderer the baker is
checked against, ``benchmarks/lighting.py``):

- ``rect``: a one-sided Lambertian rectangle (ceiling panels, windows) of ``size`` (width along
  ``u_axis``, height along ``normal × u_axis``) emitting along ``normal``; ``power_w`` W over its area,
  so its radiance is ``power_w / (π · area)``;
- ``point``: a small sphere of ``radius`` (lamps), radiant intensity ``power_w / (4π)`` W/sr.

``colour`` is a linear-RGB tint of unit luminance. ``exposure_ev`` scales the baked radiance by
``2**exposure_ev`` before the sRGB transfer (Cycles' "Standard" view); ``null`` picks it at bake time
so that the median surface reads as middle grey (an auto-exposing camera).

Placement rules (deterministic in the scene; no seed):

- **ceiling lights** on a grid over each region's polygon, spaced by venue: 0.6 m square panels every
  2.4 m in offices, clinics, schools, libraries, lobbies, stations and museums; 1.2 × 0.2 m strips every
  2 m in shops; 0.4 m flush mounts every 3 m in homes, hotels and restaurants (one per small room). A
  light needs free floor below it and 0.3 m from the walls; a region left without one gets one at its
  representative point.
- **lamps**: a point light 0.15 m below the top of every object whose label or category names a lamp.
- **windows**: the source's windows (ProcTHOR's ``windows[]``), else by rule: every exterior wall edge
  (no floor 0.6 m behind it) at least 1.6 m long gets one 1.2 m window per 3 m, sill 0.9 m, head
  2.2 m (0.25 m under the ceiling at most), clear of doorways. A window is a ``rect`` light of daylight
  on the wall's room-side face; the Gaussians draw its glazing.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from song.datasets.scenes.model import VersionedFile
from song.errors import SceneError
from song.util import write_text_atomic

LIGHTS_FILE = "lights.json"  # song.datasets.scenes.package.LIGHTS
FORMAT_NAME = "song.lights"
FORMAT_VERSION = 1

Vec3 = tuple[float, float, float]

# linear-RGB tints of unit luminance (Rec. 709 weights): 4000 K panels, 2700 K home lights, overcast daylight
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def _tint(rgb) -> Vec3:
    rgb = np.asarray(rgb, dtype=np.float64)
    return tuple(float(round(v, 4)) for v in rgb / float(rgb @ _LUMA))


NEUTRAL_WHITE = _tint([1.0, 0.89, 0.78])
WARM_WHITE = _tint([1.0, 0.76, 0.52])
DAYLIGHT = _tint([0.86, 0.93, 1.0])
# (shape, size m, grid spacing m, power W) per ceiling-light style
PANEL = ("panel", (0.6, 0.6), 2.4, 40.0)
STRIP = ("strip", (1.2, 0.2), 2.0, 30.0)
FLUSH = ("flush", (0.4, 0.4), 3.0, 22.0)
STYLE_BY_VENUE = {"shop": STRIP, "home": FLUSH, "hotel": FLUSH, "restaurant": FLUSH}
WINDOW_EXITANCE_W_M2 = 45.0  # daylight through the glazing, W per m² of window (overcast sky)
WINDOW_WIDTH_M, WINDOW_EVERY_M, WINDOW_SILL_M, WINDOW_HEAD_M = 1.2, 3.0, 0.9, 2.2
LAMP_POWER_W, LAMP_RADIUS_M = 25.0, 0.08
MAX_LIGHTS = 4096  # the baker's cost grows with texels × lights
WALL_CLEARANCE_M = 0.3


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _finite(values) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError("must be finite numbers")


class Light(_Model):
    """One light source (see the module docstring for the units)."""

    id: str
    kind: Literal["rect", "point"]
    role: Literal["ceiling", "lamp", "window"]
    position: Vec3 = Field(..., description="centre, m")
    normal: Vec3 = (0.0, 0.0, -1.0)
    u_axis: Vec3 = (1.0, 0.0, 0.0)
    size: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0
    colour: Vec3 = NEUTRAL_WHITE
    power_w: float

    @field_validator("position", "normal", "u_axis", "colour", "size")
    @classmethod
    def _vec(cls, value):
        _finite(value)
        return value

    @field_validator("power_w", "radius")
    @classmethod
    def _nonnegative(cls, value: float) -> float:
        if not math.isfinite(value) or value < 0:
            raise ValueError("must be a finite number ≥ 0")
        return value

    @field_validator("colour")
    @classmethod
    def _colour(cls, value: Vec3) -> Vec3:
        if min(value) < 0:
            raise ValueError("colour components must be ≥ 0")
        return value

    @field_validator("size")
    @classmethod
    def _size(cls, value: tuple[float, float]) -> tuple[float, float]:
        if min(value) < 0 or max(value) > 100:
            raise ValueError("size must be two lengths in [0, 100] m")
        return value

    @model_validator(mode="after")
    def _shape(self) -> Light:
        if self.kind == "rect" and min(self.size) <= 0:
            raise ValueError("a rect light needs a positive width and height (size)")
        if np.linalg.norm(self.normal) < 1e-6 or (
            self.kind == "rect" and np.linalg.norm(np.cross(self.normal, self.u_axis)) < 1e-6
        ):
            raise ValueError("normal must be non-zero and not parallel to u_axis")
        return self

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Orthonormal (u, v, normal) of a rect light, ``v = normal × u`` (u re-orthogonalised)."""
        n = np.asarray(self.normal, dtype=np.float64)
        n /= max(np.linalg.norm(n), 1e-12)
        u = np.asarray(self.u_axis, dtype=np.float64)
        u = u - (u @ n) * n
        u /= max(np.linalg.norm(u), 1e-12)
        return u, np.cross(n, u), n

    @property
    def area(self) -> float:
        """Emitting area of a rect light, m²."""
        return self.size[0] * self.size[1]

    @property
    def radiance(self) -> float:
        """Radiance of a rect light, W/(m²·sr) per unit of ``colour``."""
        return self.power_w / (math.pi * max(self.area, 1e-12))


class LightRig(VersionedFile):
    """Top level of ``lights.json``."""

    format_name: ClassVar[str] = FORMAT_NAME
    format_version: ClassVar[int] = FORMAT_VERSION

    format: str = FORMAT_NAME
    version: int = FORMAT_VERSION
    exposure_ev: float | None = None
    lights: list[Light] = Field(default=[], max_length=MAX_LIGHTS)

    @field_validator("exposure_ev")
    @classmethod
    def _exposure(cls, value: float | None) -> float | None:
        if value is not None and (not math.isfinite(value) or abs(value) > 30):
            raise ValueError("exposure_ev must be a finite number of stops in [-30, 30] or null")
        return value

    def to_json(self) -> str:
        """Canonical JSON text (two-space indent, sorted keys: diffable and editable)."""
        return json.dumps(self.model_dump(mode="json"), indent=2, sort_keys=True) + "\n"


def read_lights(path: str | Path) -> LightRig:
    """Parse ``lights.json``; :class:`SceneError` names the file and the field."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(path, "", f"cannot read ({exc})") from exc
    try:
        return LightRig.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise SceneError(path, ".".join(str(p) for p in err["loc"]) or "(top level)", err["msg"]) from exc


def write_lights(path: str | Path, rig: LightRig) -> None:
    """Write ``lights.json`` atomically."""
    write_text_atomic(Path(path), rig.to_json())


def _grid_points(polygon, spacing: float) -> np.ndarray:
    """Points on a grid of about ``spacing`` centred in the polygon's bounding box."""
    x0, y0, x1, y1 = polygon.bounds
    nx, ny = max(1, round((x1 - x0) / spacing)), max(1, round((y1 - y0) / spacing))
    gx = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
    gy = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
    return np.array([(x, y) for x in gx for y in gy])


def _ceiling_lights(dressing, smap) -> list[Light]:
    from shapely import contains_xy
    from shapely.geometry import Polygon, box

    from song.geometry.freespace import clearance_field

    grid = dressing.grid
    shape, size, spacing, power = STYLE_BY_VENUE.get(dressing.venue, PANEL)
    colour = WARM_WHITE if shape == "flush" else NEUTRAL_WHITE
    room = clearance_field(~dressing.wall_mask, grid.resolution)
    regions = [(r.id, Polygon(r.polygon)) for r in smap.regions]
    if not regions:
        x0, y0, x1, y1 = smap.bounds
        regions = [("scene", box(x0, y0, x1, y1))]
    out: list[Light] = []
    z = dressing.ceiling_height - 0.005
    for rid, polygon in regions:
        pts = _grid_points(polygon, spacing)
        inside = contains_xy(polygon, pts[:, 0], pts[:, 1])
        rc = np.clip(grid.to_cell(pts), 0, np.array(grid.shape) - 1)
        ok = inside & dressing.floor_mask[rc[:, 0], rc[:, 1]] & (room[rc[:, 0], rc[:, 1]] >= WALL_CLEARANCE_M)
        pts = pts[ok]
        if len(pts) == 0:
            p = polygon.representative_point()
            cell = np.clip(grid.to_cell(np.array([[p.x, p.y]])), 0, np.array(grid.shape) - 1)[0]
            if not dressing.floor_mask[cell[0], cell[1]]:
                continue
            pts = np.array([[p.x, p.y]])
        x0, y0, x1, y1 = polygon.bounds
        along_x = (x1 - x0) >= (y1 - y0)  # strips run along the room's long side
        for k, (x, y) in enumerate(pts):
            out.append(
                Light(
                    id=f"{rid}/{shape}_{k}",
                    kind="rect",
                    role="ceiling",
                    position=(round(float(x), 4), round(float(y), 4), round(z, 4)),
                    normal=(0.0, 0.0, -1.0),
                    u_axis=(1.0, 0.0, 0.0) if along_x else (0.0, 1.0, 0.0),
                    size=size,
                    colour=colour,
                    power_w=power,
                )
            )
    return out


def _lamps(smap) -> list[Light]:
    out = []
    for obj in smap.objects:
        if "lamp" not in f"{obj.label} {obj.category}".lower():
            continue
        fp = np.asarray(obj.footprint)
        x, y = fp.mean(axis=0)
        z = max(obj.z_min + 0.1, obj.z_max - 0.15)
        out.append(
            Light(
                id=f"{obj.id}/lamp",
                kind="point",
                role="lamp",
                position=(float(x), float(y), float(z)),
                radius=LAMP_RADIUS_M,
                colour=WARM_WHITE,
                power_w=LAMP_POWER_W,
            )  # fmt: skip
        )
    return out


def _face_distance(dressing, mid: np.ndarray, inward: np.ndarray, limit: float = 0.6) -> float | None:
    """How far from ``mid`` along ``inward`` the floor starts (the wall's room-side face), m; None if not within ``limit``."""
    step = dressing.grid.resolution / 4
    for k in range(int(limit / step) + 1):
        if _on_floor(dressing, mid + inward * k * step):
            return k * step
    return None


def _window_light(wid: str, centre_xy, u, inward, width, z0, z1) -> Light:
    """A window of ``width`` × (z1 − z0) on a wall face, emitting along ``inward``; ``u × inward`` is down."""
    area = width * (z1 - z0)
    return Light(
        id=wid,
        kind="rect",
        role="window",
        position=(round(float(centre_xy[0]), 4), round(float(centre_xy[1]), 4), round((z0 + z1) / 2, 4)),
        normal=(round(float(inward[0]), 6), round(float(inward[1]), 6), 0.0),
        u_axis=(round(float(u[0]), 6), round(float(u[1]), 6), 0.0),
        size=(round(width, 4), round(z1 - z0, 4)),
        colour=DAYLIGHT,
        power_w=round(WINDOW_EXITANCE_W_M2 * area, 3),
    )


def source_windows(dressing, windows) -> list[Light]:
    """Window lights for a source's windows (a centre-line segment each), on the side of the wall with floor.

    A window with floor on both sides (an interior window) or on neither gets no daylight.
    """
    out = []
    for k, w in enumerate(windows):
        a, b = np.asarray(w.a, dtype=np.float64), np.asarray(w.b, dtype=np.float64)
        length = float(np.linalg.norm(b - a))
        if length < 0.2:
            continue
        along = (b - a) / length
        normal = np.array([-along[1], along[0]])
        mid = (a + b) / 2
        sides = [(s, _face_distance(dressing, mid, s * normal)) for s in (1.0, -1.0)]
        found = [(s, d) for s, d in sides if d is not None]
        if len(found) != 1:
            continue
        s, d = found[0]
        inward = s * normal
        # the rect's u × v must equal its normal: u = -along when inward is the left normal of along
        u = along if s < 0 else -along
        out.append(_window_light(f"window_{k}", mid + inward * (d + 0.01), u, inward, length, w.z0, w.z1))
    return out


def rule_windows(dressing, openings) -> list[Light]:
    """Windows by rule on the exterior walls (see the module docstring)."""
    grid = dressing.grid
    top = min(WINDOW_HEAD_M, dressing.ceiling_height - 0.25)
    if top - WINDOW_SILL_M < 0.5:
        return []
    out = []
    for a, length, along, inward in wall_edges(dressing, WINDOW_WIDTH_M + 0.4):
        mid = a + along * length / 2
        if _on_floor(dressing, mid - inward * 0.6):
            continue  # floor behind: an interior wall
        if not _on_floor(dressing, mid + inward * (0.5 * grid.resolution + 0.01)):
            continue
        count = max(1, int(length // WINDOW_EVERY_M))
        width = min(WINDOW_WIDTH_M, length - 0.4)
        for i in range(count):
            c = a + along * (i + 0.5) * length / count
            if any(segment_distance(c, o.a, o.b) < width / 2 + 0.3 + o.thickness for o in openings):
                continue
            out.append(_window_light(f"window_{len(out)}", c + inward * 0.01, along, inward, width, WINDOW_SILL_M, top))
    return out


def wall_edges(dressing, min_length: float):
    """``(start, length, unit direction, unit normal into the room)`` of every wall-polygon edge ≥ ``min_length`` m.

    The rings run with the wall on their left, so the room lies on each edge's right.
    """
    for poly in dressing.walls:
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords)
            for a, b in zip(pts[:-1], pts[1:], strict=True):
                length = float(np.linalg.norm(b - a))
                if length >= min_length:
                    along = (b - a) / length
                    yield a, length, along, np.array([along[1], -along[0]])


def _on_floor(dressing, point: np.ndarray) -> bool:
    """Whether ``point`` (2,) falls on a floor cell of the dressing's grid."""
    grid = dressing.grid
    r, c = grid.to_cell(np.asarray(point)[None])[0]
    return bool(0 <= r < grid.shape[0] and 0 <= c < grid.shape[1] and dressing.floor_mask[r, c])


def segment_distance(p, a, b) -> float:
    """Distance from point ``p`` to the segment ``a``–``b`` (2-D, m)."""
    p, a, b = (np.asarray(v, dtype=np.float64) for v in (p, a, b))
    ab = b - a
    t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(a + t * ab - p))


def place_lights(dressing, smap, hints) -> LightRig:
    """The scene's lights by the module's rules (auto exposure)."""
    windows = (
        rule_windows(dressing, hints.openings) if hints.windows is None else source_windows(dressing, hints.windows)
    )
    return LightRig(lights=[*_ceiling_lights(dressing, smap), *_lamps(smap), *windows])
