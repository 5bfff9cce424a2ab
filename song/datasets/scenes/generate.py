"""Procedural scene packages: venues with rooms, a corridor, doorways and named objects.

Layout: a building of venue-dependent size with a corridor along its middle (1.2–2.5 m wide), an
entrance at its west end, and rooms on both sides, each opening onto the corridor through a doorway
0.8–1.6 m wide (open venues such as lobbies, shops and restaurants get one large hall instead of the
rooms on one side). Each room takes a role from the venue's programme (reception, open office,
consultation room, ...) and is furnished with named functional objects placed away from doorways.
Every package gets all four files: semantic map, occupancy, the Gaussian scene and the USD proxy, both
from the scene's dressing (:mod:`song.datasets.scenes.splat`; the doorways travel as dressing hints).
The same seed gives byte-identical packages.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from song.config import CrowdConfig
from song.datasets.scenes.dressing import DressingHints, Opening
from song.datasets.scenes.model import OccupancySpec, Region, SceneObject, SemanticMap
from song.datasets.scenes.package import write_scene_package
from song.datasets.scenes.raster import Rasterizer
from song.datasets.scenes.splat import SPACING_M, dress_package, write_proxy
from song.errors import SceneError, SongError
from song.geometry.freespace import components, erode
from song.util import derive_rng

RESOLUTION = 0.05
OUTER_WALL_M = 0.15
INNER_WALL_M = 0.1
WALL_HEIGHT_M = 2.6
DOOR_HEIGHT_M = 2.1  # top of the doorways
ENTRANCE_HEIGHT_M = 2.4  # top of the building entrance
BODY_RADIUS_M = CrowdConfig().agent_radius_m  # the generated layout must be one walkable part for a body this wide
DOOR_CLEAR_M = 0.9  # objects keep this far from a doorway's centre line

# (label, category, width m, depth m, height m)
Item = tuple[str, str, float, float, float]
FURNITURE: dict[str, Item] = {
    "reception_desk": ("reception desk", "reception", 2.0, 0.8, 1.1),
    "workstation": ("workstation", "workstation", 1.4, 0.7, 0.75),
    "meeting_table": ("meeting table", "table", 2.4, 1.1, 0.75),
    "printer": ("printer", "equipment", 0.6, 0.5, 1.0),
    "coffee_machine": ("coffee machine", "equipment", 0.6, 0.5, 1.2),
    "sofa": ("sofa", "seating", 2.0, 0.85, 0.8),
    "waiting_chairs": ("waiting chairs", "seating", 2.4, 0.6, 0.8),
    "counter": ("counter", "counter", 2.5, 0.7, 1.0),
    "shelf": ("shelf", "storage", 2.0, 0.5, 1.9),
    "dining_table": ("dining table", "table", 1.2, 0.8, 0.75),
    "examination_bed": ("examination bed", "furniture", 1.9, 0.7, 0.7),
    "consultation_desk": ("consultation desk", "workstation", 1.4, 0.7, 0.75),
    "bed": ("bed", "furniture", 2.0, 1.6, 0.6),
    "wardrobe": ("wardrobe", "storage", 1.6, 0.6, 2.0),
    "fridge": ("fridge", "appliance", 0.7, 0.7, 1.8),
    "kitchen_counter": ("kitchen counter", "counter", 2.2, 0.6, 0.9),
    "reading_table": ("reading table", "table", 1.8, 0.9, 0.75),
    "help_desk": ("help desk", "reception", 1.8, 0.8, 1.0),
    "luggage_rack": ("luggage rack", "storage", 1.2, 0.5, 1.0),
    "elevator": ("elevator", "transport", 1.6, 0.3, 2.4),
    "plant": ("plant", "decor", 0.5, 0.5, 1.2),
    "checkout": ("checkout", "counter", 1.8, 0.8, 1.0),
    "display_table": ("display table", "table", 1.4, 0.9, 0.8),
    "tv_stand": ("tv stand", "storage", 1.6, 0.45, 0.6),
    "bookcase": ("bookcase", "storage", 1.2, 0.35, 1.9),
    "binder_shelf": ("shelf", "storage", 1.2, 0.4, 1.8),
    "coffee_table": ("coffee table", "table", 1.1, 0.6, 0.45),
    "side_table": ("side table", "table", 0.6, 0.6, 0.55),
    "sideboard": ("sideboard", "storage", 1.6, 0.45, 0.85),
    "dresser": ("dresser", "storage", 1.2, 0.5, 0.9),
    "nightstand": ("nightstand", "storage", 0.45, 0.4, 0.55),
    "armchair": ("armchair", "seating", 0.9, 0.85, 0.85),
}
# venue → (size range ((w_min, w_max), (h_min, h_max)), open hall?, room programme: (room type, name, items))
VENUES: dict[str, tuple] = {
    "office": (
        ((14, 24), (9, 14)),
        False,
        [
            ("reception", "reception", ["reception_desk", "waiting_chairs", "plant", "side_table"]),
            (
                "open_office",
                "open office",
                ["workstation", "workstation", "workstation", "workstation", "printer", "binder_shelf", "plant"],
            ),
            ("meeting_room", "meeting room", ["meeting_table", "sideboard", "plant"]),
            ("kitchenette", "kitchenette", ["coffee_machine", "kitchen_counter", "fridge", "dining_table"]),
            ("office", "manager office", ["workstation", "bookcase", "armchair", "plant"]),
        ],
    ),
    "clinic": (
        ((14, 22), (9, 13)),
        False,
        [
            ("reception", "reception", ["reception_desk", "plant", "binder_shelf"]),
            ("waiting_area", "waiting area", ["waiting_chairs", "waiting_chairs", "side_table", "plant"]),
            ("consultation_room", "consultation room 1", ["consultation_desk", "examination_bed", "sideboard"]),
            ("consultation_room", "consultation room 2", ["consultation_desk", "examination_bed", "sideboard"]),
            ("pharmacy", "pharmacy", ["counter", "shelf"]),
        ],
    ),
    "lobby": (
        ((16, 26), (10, 15)),
        True,
        [
            ("reception", "hotel reception", ["reception_desk", "luggage_rack", "plant", "bookcase"]),
            ("lounge", "lounge", ["sofa", "sofa", "coffee_table", "armchair", "armchair", "plant"]),
            ("elevators", "elevator hall", ["elevator", "elevator", "plant"]),
            ("cafe", "lobby cafe", ["counter", "dining_table", "dining_table", "dining_table", "binder_shelf"]),
        ],
    ),
    "shop": (
        ((14, 22), (10, 14)),
        True,
        [
            ("sales_floor", "sales floor", ["shelf", "shelf", "display_table", "display_table"]),
            ("checkout", "checkout", ["checkout", "plant"]),
            ("storeroom", "storeroom", ["shelf", "shelf"]),
        ],
    ),
    "restaurant": (
        ((14, 22), (10, 14)),
        True,
        [
            (
                "dining_room",
                "dining room",
                ["dining_table", "dining_table", "dining_table", "dining_table", "sideboard", "plant"],
            ),
            ("bar", "bar", ["counter", "coffee_machine", "binder_shelf"]),
            ("kitchen", "kitchen", ["kitchen_counter", "fridge", "shelf"]),
        ],
    ),
    "home": (
        ((10, 16), (8, 12)),
        False,
        [
            ("living_room", "living room", ["sofa", "tv_stand", "coffee_table", "armchair", "bookcase", "plant"]),
            ("kitchen", "kitchen", ["kitchen_counter", "fridge", "dining_table", "sideboard"]),
            ("bedroom", "bedroom", ["bed", "wardrobe", "nightstand", "nightstand", "dresser"]),
            ("study", "study", ["workstation", "bookcase", "plant"]),
        ],
    ),
    "library": (
        ((16, 24), (10, 15)),
        True,
        [
            ("stacks", "book stacks", ["shelf", "shelf", "shelf", "shelf"]),
            ("reading_room", "reading room", ["reading_table", "reading_table"]),
            ("help_desk", "help desk", ["help_desk", "printer"]),
        ],
    ),
}
VENUE_ORDER = ("office", "clinic", "lobby", "shop", "restaurant", "home", "library")


@dataclass
class _Room:
    kind: str
    name: str
    rect: tuple[float, float, float, float]  # x0, y0, x1, y1 (inside walls)
    door: tuple[float, float, float]  # x centre, y of the wall, width
    items: list[str] = field(default_factory=list)


def _split(rng: np.random.Generator, x0: float, x1: float, n: int, min_w: float) -> list[float]:
    """N + 1 cut positions between x0 and x1, every piece at least ``min_w`` wide."""
    free = (x1 - x0) - n * min_w
    weights = rng.dirichlet(np.ones(n)) * free
    return list(np.round(x0 + np.concatenate([[0.0], np.cumsum(weights + min_w)]), 2))


def _layout(venue: str, rng: np.random.Generator):
    (wr, hr), open_hall, programme = VENUES[venue]
    width = float(np.round(rng.uniform(*wr), 1))
    height = float(np.round(rng.uniform(*hr), 1))
    corridor = float(np.round(rng.uniform(1.4, 2.4), 2))
    cy0 = float(np.round(rng.uniform(0.4, 0.6) * (height - corridor), 2))
    cy1 = cy0 + corridor
    rooms: list[_Room] = []
    program = list(programme)
    south = program[: (len(program) + 1) // 2] if not open_hall else program[:1]
    north = program[len(south) :]
    for side, entries in (("south", south), ("north", north)):
        if not entries:
            continue
        cuts = _split(rng, OUTER_WALL_M, width - OUTER_WALL_M, len(entries), 2.8)
        for k, (kind, name, items) in enumerate(entries):
            x0, x1 = (
                cuts[k] + (INNER_WALL_M / 2 if k else 0.0),
                cuts[k + 1] - (INNER_WALL_M / 2 if k < len(entries) - 1 else 0.0),
            )
            if side == "south":
                rect = (x0, OUTER_WALL_M, x1, cy0 - INNER_WALL_M / 2)
                wall_y = cy0
            else:
                rect = (x0, cy1 + INNER_WALL_M / 2, x1, height - OUTER_WALL_M)
                wall_y = cy1
            door_w = float(np.round(rng.uniform(0.9, 1.6 if open_hall else 1.2), 2))
            if open_hall and side == "north":
                door_w = min(x1 - x0 - 0.6, float(np.round(rng.uniform(2.0, 2.5), 2)))  # wide opening into the hall
            door_w = min(door_w, x1 - x0 - 1.0)
            door_x = float(np.round(rng.uniform(x0 + door_w / 2 + 0.3, x1 - door_w / 2 - 0.3), 2))
            rooms.append(_Room(kind, name, rect, (door_x, wall_y, door_w), list(items)))
    return width, height, (cy0, cy1), rooms


# a companion stands by its anchor, as in a furnished room (a coffee table before the sofa, armchairs
# at its ends): the gap to the anchor's group is its own, not the walkway kept between other furniture
COMPANIONS: dict[str, tuple[str, float]] = {"coffee_table": ("sofa", 0.4), "armchair": ("coffee_table", 0.35)}
GROUP = ("sofa", "coffee_table", "armchair")


def _rect(cx: float, cy: float, ww: float, dd: float) -> np.ndarray:
    return np.array(
        [[cx - ww / 2, cy - dd / 2], [cx + ww / 2, cy - dd / 2], [cx + ww / 2, cy + dd / 2], [cx - ww / 2, cy + dd / 2]]
    )


def _beside(anchor: np.ndarray, w: float, d: float, gap: float, room: tuple) -> list[np.ndarray]:
    """Rectangles (w along the side it faces, d across) beside each side of ``anchor``.

    Its long sides first, and of two sides the one with more room in front of it first.
    """
    (ax0, ay0), (ax1, ay1) = anchor.min(axis=0), anchor.max(axis=0)
    cx, cy = (ax0 + ax1) / 2, (ay0 + ay1) / 2
    x0, y0, x1, y1 = room
    sides = [  # (room in front of the side, rectangle)
        (y1 - ay1, _rect(cx, ay1 + gap + d / 2, w, d)),
        (ay0 - y0, _rect(cx, ay0 - gap - d / 2, w, d)),
        (x1 - ax1, _rect(ax1 + gap + d / 2, cy, d, w)),
        (ax0 - x0, _rect(ax0 - gap - d / 2, cy, d, w)),
    ]
    horizontal = ax1 - ax0 >= ay1 - ay0  # the anchor's long sides are its top and bottom
    long_sides, short_sides = (sides[:2], sides[2:]) if horizontal else (sides[2:], sides[:2])
    return [r for _, r in sorted(long_sides, key=lambda t: -t[0]) + sorted(short_sides, key=lambda t: -t[0])]


def _fits(shape, room: _Room, door, placed: list[np.ndarray], group: list[np.ndarray], margin: float) -> bool:
    """Inside the room by ``margin``, clear of its door, a walkway from all furniture but ``group`` (0.3 m)."""
    from shapely.geometry import Polygon

    x0, y0, x1, y1 = room.rect
    sx0, sy0, sx1, sy1 = shape.bounds
    if sx0 < x0 + margin or sy0 < y0 + margin or sx1 > x1 - margin or sy1 > y1 - margin:
        return False
    if shape.distance(door) < DOOR_CLEAR_M + room.door[2] / 2:
        return False
    others = [p for p in placed if not any(p is g for g in group)]
    if any(shape.distance(Polygon(p)) < 0.9 for p in others):  # a walkway between furniture
        return False
    return all(shape.distance(Polygon(p)) >= 0.3 for p in group)


def _place_items(
    room: _Room, rng: np.random.Generator, placed: list[np.ndarray]
) -> list[tuple[str, np.ndarray, float]]:
    from shapely.geometry import Point, Polygon

    x0, y0, x1, y1 = room.rect
    out = []
    door = Point(room.door[0], room.door[1])
    for item in room.items:
        label, category, w, d, h = FURNITURE[item]
        group = [c for it, c, _ in out if it in GROUP]
        anchors = [c for it, c, _ in out if item in COMPANIONS and it == COMPANIONS[item][0]]
        done = False
        for anchor in anchors:
            for corners in _beside(anchor, w, d, COMPANIONS[item][1], room.rect):
                corners = np.round(corners, 3)
                if _fits(Polygon(corners), room, door, placed, group, 0.05):
                    placed.append(corners)
                    out.append((item, corners, h))
                    done = True
                    break
            if done:
                break
        for _ in range(0 if done else 60):
            rotate = rng.random() < 0.5
            ww, dd = (d, w) if rotate else (w, d)
            if ww > x1 - x0 - 0.8 or dd > y1 - y0 - 0.8:
                continue
            against_wall = rng.random() < 0.5
            cx = rng.uniform(x0 + 0.4 + ww / 2, x1 - 0.4 - ww / 2)
            if against_wall:
                cy = (y0 + dd / 2 + 0.05) if rng.random() < 0.5 else (y1 - dd / 2 - 0.05)
            else:
                cy = rng.uniform(y0 + 0.4 + dd / 2, y1 - 0.4 - dd / 2)
            corners = np.round(_rect(cx, cy, ww, dd), 3)
            if not _fits(Polygon(corners), room, door, placed, [], 0.0):
                continue
            placed.append(corners)
            out.append((item, corners, h))
            break
    return out


def _wall(raster: Rasterizer, a, b, thickness: float) -> None:
    """Draw a wall strip into the occupancy image."""
    raster.segment(np.array(a, float), np.array(b, float), thickness, 0)


def _draw_walls(
    raster: Rasterizer, width: float, height: float, corridor: tuple, rooms: list, entrance_w: float
) -> None:
    """The outer walls (an entrance gap on the west, on the corridor) and each room's wall with its door."""
    cy0, cy1 = corridor
    t = OUTER_WALL_M / 2
    ey = (cy0 + cy1) / 2
    _wall(raster, (t, t), (width - t, t), OUTER_WALL_M)
    _wall(raster, (width - t, t), (width - t, height - t), OUTER_WALL_M)
    _wall(raster, (width - t, height - t), (t, height - t), OUTER_WALL_M)
    _wall(raster, (t, height - t), (t, ey + entrance_w / 2), OUTER_WALL_M)
    _wall(raster, (t, ey - entrance_w / 2), (t, t), OUTER_WALL_M)
    for room in rooms:
        x0, _, x1, _ = room.rect
        dx, wy, dw = room.door
        _wall(raster, (x0 - INNER_WALL_M / 2 if x0 > OUTER_WALL_M else x0, wy), (dx - dw / 2, wy), INNER_WALL_M)
        right = x1 + INNER_WALL_M / 2 if x1 < width - OUTER_WALL_M else x1
        _wall(raster, (dx + dw / 2, wy), (right, wy), INNER_WALL_M)
        if x1 < width - OUTER_WALL_M - 0.01:
            far = room.rect[1] if wy == cy1 else room.rect[3]
            _wall(raster, (x1 + INNER_WALL_M / 2, wy), (x1 + INNER_WALL_M / 2, far), INNER_WALL_M)


def _openings(corridor: tuple, rooms: list, entrance_w: float) -> list[Opening]:
    """The entrance and every room's door, as dressing openings."""
    t, ey = OUTER_WALL_M / 2, (corridor[0] + corridor[1]) / 2
    entrance = Opening((t, ey - entrance_w / 2), (t, ey + entrance_w / 2), ENTRANCE_HEIGHT_M, OUTER_WALL_M)
    doors = [
        Opening(
            (r.door[0] - r.door[2] / 2, r.door[1]), (r.door[0] + r.door[2] / 2, r.door[1]), DOOR_HEIGHT_M, INNER_WALL_M
        )
        for r in rooms
    ]
    return [entrance, *doors]


def _furnish(rooms: list, rng: np.random.Generator, raster: Rasterizer) -> tuple[list[Region], list[SceneObject]]:
    """Each room's region and furniture (drawn into the raster), in room order."""
    placed: list[np.ndarray] = []
    regions, objects, counts = [], [], {}
    for k, room in enumerate(rooms):
        rid = f"{room.kind}_{k + 1}"
        x0, y0, x1, y1 = room.rect
        regions.append(Region(id=rid, type=room.kind, name=room.name, polygon=[(x0, y0), (x1, y0), (x1, y1), (x0, y1)]))
        for item, corners, h in _place_items(room, rng, placed):
            counts[item] = counts.get(item, 0) + 1
            label, category = FURNITURE[item][:2]
            footprint = [tuple(c) for c in corners.tolist()]
            objects.append(
                SceneObject(id=f"{item}_{counts[item]}", label=label, category=category, footprint=footprint,
                            z_max=h, region=rid)
            )  # fmt: skip
            raster.polygon(corners, 0)
    return regions, objects


def _entrance(corridor: tuple, entrance_w: float) -> SceneObject:
    """The entrance as an object of the corridor (people come in and go out there)."""
    ey, ex = (corridor[0] + corridor[1]) / 2, OUTER_WALL_M + 0.05
    footprint = [
        (0.0, ey - entrance_w / 2),
        (ex, ey - entrance_w / 2),
        (ex, ey + entrance_w / 2),
        (0.0, ey + entrance_w / 2),
    ]
    return SceneObject(
        id="entrance_1", label="entrance", category="entrance", region="corridor", footprint=footprint, z_max=2.2
    )


def _attempt(venue: str, rng: np.random.Generator):
    """One draw of a venue: ``(width, height, regions, objects, openings, cells, connected)``."""
    width, height, corridor, rooms = _layout(venue, rng)
    raster = Rasterizer((0.0, 0.0), (width, height), RESOLUTION, fill=255)
    entrance_w = float(np.round(rng.uniform(1.2, min(2.2, corridor[1] - corridor[0])), 2))
    _draw_walls(raster, width, height, corridor, rooms, entrance_w)
    hall = Region(
        id="corridor", type="corridor", name="corridor",
        polygon=[(0.0, corridor[0]), (width, corridor[0]), (width, corridor[1]), (0.0, corridor[1])],
    )  # fmt: skip
    regions, objects = _furnish(rooms, rng, raster)
    cells = raster.cells
    _, n_parts = components(erode(cells == 255, RESOLUTION, BODY_RADIUS_M))
    openings = _openings(corridor, rooms, entrance_w)
    return width, height, [hall, *regions], [*objects, _entrance(corridor, entrance_w)], openings, cells, n_parts == 1


def generate_scene(
    scene_id: str, venue: str, seed: int, out_dir: str | Path, splat: bool = True, spacing: float = SPACING_M
) -> Path:
    """One procedural package ``out_dir/scene_id`` for ``venue``; deterministic in (seed, scene_id).

    Up to eight draws, until one whose walkable space is one connected part. The USD proxy is always
    written (it carries the doorways as dressing hints); the Gaussian scene too unless ``splat`` is
    False (``song scenes splat`` can add it later, identically).
    """
    for attempt in range(8):
        width, height, regions, objects, openings, cells, connected = _attempt(
            venue, derive_rng(seed, scene_id, "generate", attempt)
        )
        if connected:
            break
    smap = SemanticMap(
        scene_id=scene_id,
        venue_type=venue,
        source="procedural",
        name=f"procedural {venue}",
        licence="CC0 (generated by SONG)",
        bounds=(0.0, 0.0, width, height),
        occupancy=OccupancySpec(resolution=RESOLUTION, origin=(0.0, 0.0)),
        regions=regions,
        objects=objects,
    )
    _refuse_overwrite(Path(out_dir) / scene_id, smap, cells)
    root = write_scene_package(Path(out_dir) / scene_id, smap, cells)
    hints = DressingHints(openings=tuple(openings), ceiling_height_m=WALL_HEIGHT_M, seed=seed)
    if splat:
        dress_package(root, hints, spacing)
    else:
        write_proxy(root, hints)
    return root


def _refuse_overwrite(root: Path, smap: SemanticMap, cells: np.ndarray) -> None:
    """Refuse to replace a package that holds a different scene (e.g. made with another seed)."""
    if not (root / "semantic_map.json").exists():
        return
    from song.datasets.scenes import load_scene_package

    try:
        old = load_scene_package(root)
        same = old.semantic_map == smap and np.array_equal(old.occupancy.cells, cells)
    except SongError:
        same = False
    if not same:
        raise SceneError(
            root / "semantic_map.json",
            "scene_id",
            "a different package is already there (another seed?); generate into another --out or remove it first",
        )


def generate_scenes(
    count: int,
    seed: int,
    out_dir: str | Path,
    venues: tuple[str, ...] = VENUE_ORDER,
    splat: bool = True,
    spacing: float = SPACING_M,
    workers: int = 1,
) -> list[Path]:
    """``count`` packages cycling through ``venues`` (ids ``<venue>_<k>``), on ``workers`` processes.

    Each package depends only on its id, venue and the seed: the same bytes whatever the worker count.
    """
    from song.parallel import parallel_map

    jobs = [
        (f"{venues[k % len(venues)]}_{k:04d}", venues[k % len(venues)], seed, str(out_dir), splat, spacing)
        for k in range(count)
    ]
    return sorted(parallel_map(_generate_job, jobs, workers))


def _generate_job(job: tuple) -> Path:
    return generate_scene(*job)
