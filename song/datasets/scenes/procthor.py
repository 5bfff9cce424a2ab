"""ProcTHOR house JSON → scene packages (DESIGN §4.4).

ProcTHOR (Unity) is Y-up and left-handed: x right, y up, z forward. :func:`unity_to_world` maps a
Unity point (x, y, z) to ours (X, Y, Z) = (x, z, y): swapping y and z is a reflection, which turns the
left-handed frame into a right-handed one and keeps the floor plan as seen from above (Unity's top
view shows x right, z up; ours shows X right, Y up). Unity yaw ψ turns +z toward +x (clockwise from
above); in our frame an object's forward axis is (sin ψ, cos ψ) and its right axis (cos ψ, −sin ψ).

Walls are zero-thickness planes (an interior wall appears once per side); they become occupied strips
``wall_thickness_m`` thick centred on the plane. Door holes (``holePolygon``, wall-local x = distance
from the wall's first end) are cut back open across the strip so rooms connect. Floor objects (bottom
within 0.15 m of the floor) get footprints from the asset size table; wall-mounted and small objects
on furniture are skipped. Everything outside the rooms is occupied.
"""

from __future__ import annotations

import gzip
import json
import re
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.scenes.model import OccupancySpec, Region, SceneObject, SemanticMap
from song.datasets.scenes.package import write_scene_package
from song.datasets.scenes.raster import Rasterizer
from song.errors import SceneError, SongError

FLOOR_OBJECT_MAX_BOTTOM_M = 0.15
MIN_FOOTPRINT_M = 0.15  # smaller floor objects (bins, plungers) are not navigation obstacles
MARGIN_M = 0.3
CATEGORIES = {
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
    """One imported house: its package folder, or the error that stopped it."""

    scene_id: str
    path: Path | None
    error: str = ""


def load_asset_table(path: Path | None = None) -> dict[str, Any]:
    """The asset size table (the shipped one by default)."""
    if path is None:
        text = resources.files("song.datasets.scenes").joinpath("data/procthor_asset_bboxes.json").read_text()
    else:
        text = Path(path).read_text(encoding="utf-8")
    return json.loads(text)


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


def _wall_ends(wall_id: str) -> tuple[np.ndarray, np.ndarray]:
    parts = wall_id.split("|")
    x0, z0, x1, z1 = (float(v) for v in parts[-4:])
    return np.array([x0, z0]), np.array([x1, z1])


def convert_house(house: dict, scene_id: str, assets: dict[str, Any], resolution: float, wall: float, where: str):
    """A ProcTHOR house dict → (SemanticMap, occupancy cells)."""
    try:
        rooms = _room_polygons(house)
    except (KeyError, TypeError, ValueError) as exc:
        raise SceneError(where, "rooms", f"cannot read floor polygons: {exc}") from exc
    if not rooms:
        raise SceneError(where, "rooms", "house has no rooms")
    allpts = np.vstack(list(rooms.values()))
    lo = np.floor((allpts.min(axis=0) - MARGIN_M) / resolution) * resolution
    hi = np.ceil((allpts.max(axis=0) + MARGIN_M) / resolution) * resolution
    raster = Rasterizer(tuple(lo), tuple(hi), resolution, fill=0)
    for poly in rooms.values():
        raster.polygon(poly, 255)
    doors = {}
    for door in house.get("doors", []):
        for key in ("wall0", "wall1"):
            if door.get(key):
                hole = door["holePolygon"]
                doors.setdefault(door[key], []).append((hole[0]["x"], hole[1]["x"]))
    for wall_def in house.get("walls", []):
        a, b = _wall_ends(wall_def["id"])
        raster.segment(a, b, wall, 0)
    for wall_id, holes in doors.items():
        a, b = _wall_ends(wall_id)
        direction = (b - a) / max(np.linalg.norm(b - a), 1e-9)
        for x_lo, x_hi in holes:
            raster.segment(a + direction * x_lo, a + direction * x_hi, wall + 2 * resolution, 255, caps=False)
    regions = []
    room_ids = {}
    for index, room in enumerate(house["rooms"]):
        rid = f"{_snake(room['roomType'])}_{index + 1}"
        room_ids[room["id"]] = rid
        poly = [tuple(p) for p in rooms[room["id"]].tolist()]
        regions.append(
            Region(id=rid, type=_snake(room["roomType"]), name=ROOM_NAMES.get(room["roomType"]), polygon=poly)
        )
    objects, counters = [], {}
    from shapely.geometry import Point, Polygon

    shapes = {rid: Polygon(rooms[k]) for k, rid in room_ids.items()}
    for obj in house.get("objects", []):
        asset = assets.get(obj.get("assetId", ""))
        if asset is None:
            continue
        box = asset["boundingBox"]
        pos = obj["position"]
        if pos["y"] - box["y"] / 2 > FLOOR_OBJECT_MAX_BOTTOM_M or max(box["x"], box["z"]) < MIN_FOOTPRINT_M:
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
    return smap, raster.cells


def import_procthor(
    src: str | Path,
    out_dir: str | Path,
    resolution: float = 0.05,
    wall_thickness: float = 0.1,
    assets: Path | None = None,
) -> list[ImportResult]:
    """Import every house under ``src`` into ``out_dir/<procthor_name>/``; a bad house fails alone."""
    src, out_dir = Path(src), Path(out_dir)
    table = load_asset_table(assets)
    results = []
    for name, house in iter_houses(src):
        scene_id = f"procthor_{name}".replace(" ", "_")
        try:
            if isinstance(house, Exception):
                raise house
            smap, cells = convert_house(house, scene_id, table, resolution, wall_thickness, str(src))
            results.append(ImportResult(scene_id, write_scene_package(out_dir / scene_id, smap, cells)))
        except SongError as exc:
            results.append(ImportResult(scene_id, None, str(exc)))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            results.append(ImportResult(scene_id, None, f"{src}: {name}: malformed house: {exc}"))
    return results
