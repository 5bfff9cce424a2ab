"""ProcTHOR house JSON → scene packages.

ProcTHOR (Unity) is Y-up and left-handed: x right, y up, z forward. :func:`unity_to_world` maps a
Unity point (x, y, z) to ours (X, Y, Z) = (x, z, y): swapping y and z is a reflection, which turns the
left-handed frame into a right-handed one and keeps the floor plan as seen from above (Unity's top
view shows x right, z up; ours shows X right, Y up). Unity yaw ψ turns +z toward +x (clockwise from
above); in our frame an object's forward axis is (sin ψ, cos ψ) and its right axis (cos ψ, −sin ψ).

Walls are zero-thickness planes (an interior wall appears once per side); they become occupied strips
``wall_thickness_m`` thick centred on the plane. A wall marked ``"empty": true`` is an open-plan
connection (ProcTHOR opens the whole boundary between, e.g., a kitchen and a living room that way): it
has no geometry in AI2-THOR, so it is not drawn at all and people walk through it.

A door or window's ``holePolygon`` is in the local frame of its ``wall0``: x is the distance along the
wall from the **first corner of that wall's polygon** toward its second, y the height. That is how
ProcTHOR places them (``allenai/procthor``, ``procthor/generation/doors.py``: ``ProceduralFrame.polygon``
measures the door from the wall's maximum corner when the polygon's first corner is the larger one) and
how AI2-THOR cuts the hole in the wall mesh it builds from that polygon. The two sides of an interior
wall run in opposite directions, so measuring from the wall id's (sorted) corners mirrors the hole
whenever ``wall0``'s polygon runs from its larger corner. Door holes are cut back open across the
strip so rooms connect; window holes do not touch the floor plan (they sit above a sill). Floor objects (bottom
within 0.15 m of the floor) get footprints from ProcTHOR's asset database (the ``procthor`` package's
``databases/asset-database.json``, or a file the user names); wall-mounted and small objects on
furniture are skipped, and objects whose asset is missing from the database are counted and reported
per house (never silently). Everything outside the rooms is occupied.

Fields read: ``rooms[].id/roomType/floorPolygon/floorMaterial``; ``walls[].id/polygon/empty/material``
(the polygon's first two corners give the wall's ends and direction; the id's corners only when the
polygon is missing); ``doors[].id/wall0/wall1/holePolygon``; ``objects[].assetId/position/rotation.y``
(floor objects are obstacles; objects standing higher up and ``objects[].children[]``, the objects
placed on others, become small items of the dressing, seen but not obstacles,
:mod:`song.datasets.scenes.clutter`).
``windows[].wall0/holePolygon`` become the scene's windows (glazing and daylight,
:mod:`song.datasets.scenes.lights`; no effect on the floor plan). Deliberately ignored: an object's
``rotation.x/z`` (ProcTHOR's floor objects stand upright), ``kinematic`` (every floor object is an obstacle), ``openness``
(a door is always passable, as a pedestrian opens it), ``room0/room1`` (the hole's wall says where it is),
lights, skybox and ``metadata``.

The importer also dresses the house (:mod:`song.datasets.scenes.splat`): its doors become openings
(lintels above the hole), its rooms' floor materials and wall paint map to ours, its wall height is
the ceiling; the USD proxy and the Gaussian scene are written with the package.
"""

from __future__ import annotations

import dataclasses
import gzip
import json
import re
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.limits import limits
from song.datasets.scenes.dressing import DressingHints, Item, Opening, Window
from song.datasets.scenes.materials import procthor_floor_material
from song.datasets.scenes.model import OccupancySpec, Region, SceneObject, SemanticMap
from song.datasets.scenes.package import write_scene_package
from song.datasets.scenes.raster import Rasterizer
from song.datasets.scenes.splat import SPACING_M, dress_package, write_proxy
from song.errors import SceneError, SongError

FLOOR_OBJECT_MAX_BOTTOM_M = 0.15
MIN_FOOTPRINT_M = 0.05  # floor objects smaller than one grid cell (candles, eggs) cannot be drawn on the map
MARGIN_M = 0.3
MAX_COORD_M = 1.0e5  # a house coordinate beyond 100 km is a broken file
CATEGORIES = {
    "Television": "appliance",
    "FloorLamp": "decor",
    "HousePlant": "decor",
    "GarbageCan": "fixture",
    "Ottoman": "seating",
    "Stool": "seating",
    "Safe": "storage",
    "LaundryHamper": "storage",
    "Microwave": "appliance",
    "WashingMachine": "appliance",
    "ClothesDryer": "appliance",
    "Bed": "furniture",
    "Sofa": "seating",
    "ArmChair": "seating",
    "Chair": "seating",
    "DiningTable": "table",
    "CoffeeTable": "table",
    "SideTable": "table",
    "Desk": "workstation",
    "Dresser": "storage",
    "Shelf": "storage",
    "ShelvingUnit": "storage",
    "TVStand": "storage",
    "CounterTop": "counter",
    "Fridge": "appliance",
    "Toilet": "fixture",
    "Sink": "fixture",
    "Bathtub": "fixture",
}
ROOM_NAMES = {"LivingRoom": "living room", "Kitchen": "kitchen", "Bedroom": "bedroom", "Bathroom": "bathroom"}


def unity_to_world(points: np.ndarray) -> np.ndarray:
    """(..., 3) Unity (x, y, z) → (..., 3) SONG (x, z, y). Its own inverse."""
    points = np.asarray(points, dtype=np.float64)
    return points[..., [0, 2, 1]]


def unity_yaw_axes(yaw_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """An object's right and forward axes in our x-y plane for a Unity yaw (degrees)."""
    psi = np.deg2rad(yaw_deg)
    return np.array([np.cos(psi), -np.sin(psi)]), np.array([np.sin(psi), np.cos(psi)])


@dataclass(frozen=True)
class ImportResult:
    """One imported house: its package folder (or the error that stopped it) and its unsized objects."""

    scene_id: str
    path: Path | None
    error: str = ""
    unsized: int = 0  # floor-level objects whose asset is missing from the database (skipped)

    @property
    def warning(self) -> str:
        """A one-line warning when objects could not be sized, else ""."""
        if not self.unsized:
            return ""
        return f"{self.scene_id}: {self.unsized} object(s) skipped: their assets are not in the asset database"


ASSET_DB = "databases/asset-database.json"


def load_asset_table(path: str | Path | None = None) -> dict[str, Any]:
    """``{assetId: {"objectType", "boundingBox"}}`` from ProcTHOR's asset database.

    Args:
        path: a database file -- ProcTHOR's format (``{objectType: [asset, ...]}``) or the flat
            ``{assetId: {objectType, boundingBox}}`` form; default the ``procthor`` package's own.

    Raises:
        MissingDependencyError: no ``path`` and the ``procthor`` package is not installed.
        SceneError: the file cannot be read or has neither form.
    """
    if path is None:
        try:
            source = resources.files("procthor").joinpath(ASSET_DB)
            text = source.read_text(encoding="utf-8")
        except (ModuleNotFoundError, FileNotFoundError) as exc:
            from song.errors import MissingDependencyError

            raise MissingDependencyError("procthor", "procthor") from exc
        where = f"procthor/{ASSET_DB}"
    else:
        where = str(path)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneError(path, "", f"cannot read the asset database: {exc}") from exc
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise SceneError(where, "", f"asset database is not JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise SceneError(where, "", "asset database must be a JSON object")
    table: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, list):  # ProcTHOR's own form: objectType -> assets
            for asset in value:
                if isinstance(asset, dict) and "assetId" in asset and "boundingBox" in asset:
                    table[asset["assetId"]] = {
                        "objectType": asset.get("objectType", key),
                        "boundingBox": asset["boundingBox"],
                    }
        elif isinstance(value, dict) and "boundingBox" in value:
            table[key] = value
    if not table:
        raise SceneError(where, "", "no assets with a boundingBox found")
    return table


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def iter_houses(src: Path) -> Iterator[tuple[str, Any]]:
    """(name, house dict or exception) from a house file, a folder of them, or a .jsonl[.gz]."""
    if src.is_dir():
        for path in sorted(src.iterdir()):
            if path.name.startswith("house") or path.suffix in (".json", ".jsonl", ".gz"):
                if path.suffix == ".json" and path.name != "asset_bboxes.json":
                    yield from iter_houses(path)
        return
    if src.name.endswith((".jsonl", ".jsonl.gz")):
        opener = gzip.open if src.name.endswith(".gz") else open
        with opener(src, "rt", encoding="utf-8") as handle:
            for index, line in enumerate(handle):
                if line.strip():
                    try:
                        yield f"{src.name.split('.')[0]}_{index}", json.loads(line)
                    except ValueError as exc:
                        yield (
                            f"{src.name.split('.')[0]}_{index}",
                            SceneError(src, f"line {index + 1}", f"not JSON: {exc}"),
                        )
        return
    try:
        yield src.stem, json.loads(src.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        yield src.stem, SceneError(src, "", f"not a readable house JSON: {exc}")


def _room_polygons(house: dict) -> dict[str, np.ndarray]:
    return {
        room["id"]: unity_to_world(np.array([[p["x"], p["y"], p["z"]] for p in room["floorPolygon"]]))[:, :2]
        for room in house["rooms"]
    }


def _wall_ends(wall: dict) -> tuple[np.ndarray, np.ndarray]:
    """A wall's two ends (our x, y) in the order of its polygon: its hole coordinates start at the first.

    ProcTHOR writes a wall's polygon as its two floor corners, then the same two at the top; a wall
    without a polygon falls back to the corners in its id (``wall|room|x0|z0|x1|z1``, sorted, 2 decimals).
    """
    poly = wall.get("polygon") or []
    if len(poly) >= 2:
        floor = min(float(p.get("y", 0.0)) for p in poly)
        ends = [np.array([float(p["x"]), float(p["z"])]) for p in poly if float(p.get("y", 0.0)) <= floor + 1e-6]
        if len(ends) >= 2 and np.linalg.norm(ends[1] - ends[0]) > 1e-9:
            return ends[0], ends[1]
    parts = str(wall["id"]).split("|")
    x0, z0, x1, z1 = (float(v) for v in parts[-4:])
    return np.array([x0, z0]), np.array([x1, z1])


def _hole_segments(house: dict, key: str) -> list[tuple[str, np.ndarray, np.ndarray, float, float]]:
    """``(id, a, b, bottom, top)`` per door or window (``key``): its hole's ends along its wall, its bottom and top (m).

    The hole's x runs along ``wall0`` from the first corner of its polygon (see the module docstring);
    a hole whose ``wall0`` is not among the walls is measured along ``wall1`` from its far end.
    """
    walls = {w.get("id"): w for w in house.get("walls", []) if isinstance(w, dict)}
    out, seen = [], set()
    for item in house.get(key, []):
        hole = item.get("holePolygon") or []
        if len(hole) < 2 or item.get("id") in seen:
            continue
        seen.add(item.get("id"))
        if item.get("wall0") in walls:
            a, b = _wall_ends(walls[item["wall0"]])
        elif item.get("wall1") in walls:
            b, a = _wall_ends(walls[item["wall1"]])
        else:
            continue
        direction = (b - a) / max(np.linalg.norm(b - a), 1e-9)
        lo, hi = sorted((float(hole[0]["x"]), float(hole[1]["x"])))
        top = max(float(hole[0].get("y", 2.1)), float(hole[1].get("y", 2.1)))
        bottom = min(float(hole[0].get("y", 0.0)), float(hole[1].get("y", 0.0)))
        out.append((str(item.get("id")), a + direction * lo, a + direction * hi, bottom, top))
    return out


@dataclass(frozen=True)
class ConvertedHouse:
    """A house as a package: semantic map, occupancy cells, dressing hints, unsized object count."""

    semantic_map: SemanticMap
    cells: np.ndarray
    hints: DressingHints
    unsized: int


WALL_TINT_MIX = 0.5  # ProcTHOR's wall colours tint a lit white texture; mixed halfway to white they read as paint


def _rgb_hex(colour: dict) -> str:
    values = [WALL_TINT_MIX + (1 - WALL_TINT_MIX) * float(colour.get(k, 0.8)) for k in ("r", "g", "b")]
    r, g, b = (min(255, max(0, int(round(255 * v)))) for v in values)
    return f"paint:#{r:02x}{g:02x}{b:02x}"


def _hints(house: dict, room_ids: dict[str, str], wall: float) -> DressingHints:
    """Openings from the doors, floor materials per room, the most common wall paint, the wall height."""
    openings = [Opening(tuple(a), tuple(b), top, wall) for _, a, b, _, top in _hole_segments(house, "doors")]
    windows = [
        Window(tuple(float(v) for v in a), tuple(float(v) for v in b), round(z0, 3), round(z1, 3))
        for _, a, b, z0, z1 in _hole_segments(house, "windows")
        if z1 > z0 + 0.1
    ]
    floors = {
        room_ids[room["id"]]: procthor_floor_material(room.get("floorMaterial", {}).get("name", ""))
        for room in house.get("rooms", [])
        if room.get("id") in room_ids
    }
    paints = [
        _rgb_hex(w["material"]["color"])
        for w in house.get("walls", [])
        if isinstance(w.get("material", {}).get("color"), dict)
    ]
    heights = [
        float(p["y"]) for w in house.get("walls", []) for p in w.get("polygon", []) if isinstance(p, dict) and "y" in p
    ]
    return DressingHints(
        openings=tuple(openings),
        floor_materials=floors,
        wall_material=max(set(paints), key=paints.count) if paints else None,
        ceiling_height_m=round(max(heights), 3) if heights else None,
        windows=tuple(windows),
    )


def convert_house(
    house: dict, scene_id: str, assets: dict[str, Any], resolution: float, wall: float, where: str
) -> ConvertedHouse:
    """A ProcTHOR house dict → a :class:`ConvertedHouse`."""
    try:
        rooms = _room_polygons(house)
    except (KeyError, TypeError, ValueError) as exc:
        raise SceneError(where, "rooms", f"cannot read floor polygons: {exc}") from exc
    if not rooms:
        raise SceneError(where, "rooms", "house has no rooms")
    allpts = np.vstack(list(rooms.values()))
    if not np.isfinite(allpts).all() or np.abs(allpts).max() > MAX_COORD_M:
        raise SceneError(where, "rooms", f"floor polygon coordinates must be finite and within ±{MAX_COORD_M:g} m")
    lo = np.floor((allpts.min(axis=0) - MARGIN_M) / resolution) * resolution
    hi = np.ceil((allpts.max(axis=0) + MARGIN_M) / resolution) * resolution
    cells = int(np.prod(np.round((hi - lo) / resolution)))
    if cells > limits().max_image_pixels:  # refused before any grid is allocated
        size = "x".join(f"{v:.0f}" for v in hi - lo)
        raise SceneError(where, "rooms", f"a {size} m house is {cells:,} cells at {resolution} m (max_image_pixels)")
    raster = Rasterizer(tuple(lo), tuple(hi), resolution, fill=0)
    for poly in rooms.values():
        raster.polygon(poly, 255)
    for wall_def in house.get("walls", []):
        if wall_def.get("empty") is True:  # an open-plan connection: no geometry in AI2-THOR
            continue
        a, b = _wall_ends(wall_def)
        raster.segment(a, b, wall, 0)
    for _, a, b, _, _ in _hole_segments(house, "doors"):
        raster.segment(a, b, wall + 2 * resolution, 255, caps=False)
    regions = []
    room_ids = {}
    for index, room in enumerate(house["rooms"]):
        rid = f"{_snake(room['roomType'])}_{index + 1}"
        room_ids[room["id"]] = rid
        poly = [tuple(p) for p in rooms[room["id"]].tolist()]
        regions.append(
            Region(id=rid, type=_snake(room["roomType"]), name=ROOM_NAMES.get(room["roomType"]), polygon=poly)
        )
    objects, counters, unsized = [], {}, 0
    from shapely.geometry import Point, Polygon

    shapes = {rid: Polygon(rooms[k]) for k, rid in room_ids.items()}
    items = []
    for obj in house.get("objects", []):
        asset = assets.get(obj.get("assetId", ""))
        pos = obj["position"]
        items += [item for child in obj.get("children", []) or [] if (item := _item(child, assets))]
        if asset is None:
            unsized += float(pos.get("y", 0.0)) < 1.0  # floor-level objects we could not size
            continue
        box = asset["boundingBox"]
        if pos["y"] - box["y"] / 2 > FLOOR_OBJECT_MAX_BOTTOM_M or max(box["x"], box["z"]) < MIN_FOOTPRINT_M:
            if item := _item(obj, assets):  # a small or hanging object: seen, not an obstacle
                items.append(item)
            continue
        centre = np.array([pos["x"], pos["z"]])
        right, forward = unity_yaw_axes(obj.get("rotation", {}).get("y", 0.0))
        corners = [
            centre + sx * box["x"] / 2 * right + sz * box["z"] / 2 * forward
            for sx, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
        kind = asset["objectType"]
        label = _snake(kind)
        counters[label] = counters.get(label, 0) + 1
        region = next((rid for rid, shape in shapes.items() if shape.contains(Point(centre))), None)
        footprint = [tuple(c) for c in np.round(corners, 4).tolist()]
        objects.append(
            SceneObject(
                id=f"{label}_{counters[label]}",
                label=label.replace("_", " "),
                category=CATEGORIES.get(kind, "furniture"),
                footprint=footprint,
                z_min=0.0,
                z_max=round(float(box["y"]), 3),
                region=region,
            )
        )
        raster.polygon(np.array(footprint), 0)
    smap = SemanticMap(
        scene_id=scene_id,
        venue_type="home",
        source="procthor",
        licence="Apache-2.0 (ProcTHOR)",
        bounds=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
        occupancy=OccupancySpec(resolution=resolution, origin=(float(lo[0]), float(lo[1]))),
        regions=regions,
        objects=objects,
    )
    hints = dataclasses.replace(_hints(house, room_ids, wall), items=tuple(items))
    return ConvertedHouse(smap, raster.cells, hints, unsized)


def _item(obj: dict, assets: dict[str, Any]) -> Item | None:
    """A ProcTHOR object as a small item: its asset's box at its position (None when the asset is unknown)."""
    asset = assets.get(obj.get("assetId", "")) if isinstance(obj, dict) else None
    pos = obj.get("position") if isinstance(obj, dict) else None
    if asset is None or not isinstance(pos, dict):
        return None
    box = asset["boundingBox"]
    try:
        x, y, z = float(pos["x"]), float(pos["y"]), float(pos["z"])
        yaw_deg = float((obj.get("rotation") or {}).get("y", 0.0))
        sx, sy, sz = float(box["x"]), float(box["y"]), float(box["z"])
    except (KeyError, TypeError, ValueError):
        return None
    if not all(np.isfinite([x, y, z, yaw_deg, sx, sy, sz])) or min(sx, sy, sz) <= 0:
        return None
    right, _ = unity_yaw_axes(yaw_deg)
    yaw = round(float(np.arctan2(right[1], right[0])), 4)
    return Item(_snake(asset["objectType"]).replace("_", " "), (round(x, 4), round(z, 4)), yaw,
                (round(sx / 2, 4), round(sz / 2, 4)), round(y - sy / 2, 4), round(y + sy / 2, 4))  # fmt: skip


def import_procthor(
    src: str | Path,
    out_dir: str | Path,
    resolution: float = 0.05,
    wall_thickness: float = 0.1,
    assets: Path | None = None,
    splat: bool = True,
    spacing: float = SPACING_M,
) -> list[ImportResult]:
    """Import every house under ``src`` into ``out_dir/<procthor_name>/``; a bad house fails alone.

    Each package gets its USD proxy (with the house's dressing hints) and, unless ``splat`` is False,
    its Gaussian scene.
    """
    src, out_dir = Path(src), Path(out_dir)
    table = load_asset_table(assets)
    results = []
    for name, house in iter_houses(src):
        scene_id = f"procthor_{name}".replace(" ", "_")
        try:
            if isinstance(house, Exception):
                raise house
            house_pkg = convert_house(house, scene_id, table, resolution, wall_thickness, str(src))
            root = write_scene_package(out_dir / scene_id, house_pkg.semantic_map, house_pkg.cells)
            if splat:
                dress_package(root, house_pkg.hints, spacing)
            else:
                write_proxy(root, house_pkg.hints)
            results.append(ImportResult(scene_id, root, unsized=house_pkg.unsized))
        except SongError as exc:
            results.append(ImportResult(scene_id, None, str(exc)))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            results.append(ImportResult(scene_id, None, f"{src}: {name}: malformed house: {exc}"))
    return results
