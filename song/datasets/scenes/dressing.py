"""A scene's visible structure, derived deterministically from its semantic map and occupancy grid.

Both the Gaussian scene (:mod:`song.datasets.scenes.splat`) and the USD proxy come from one
:class:`Dressing`, so they agree with each other and with the occupancy map:

- **walls**: the occupied cells that no object covers, traced into polygons (¼ cell inside the cells'
  edges, straightened within half a cell) and extruded from the floor to the ceiling;
- **floor** and **ceiling**: every cell that is free or under an object;
- **openings** (doorways, known to the generator and the ProcTHOR importer): a lintel from the door
  top to the ceiling and a trim around the opening;
- **furniture**: every object's parts by category (:mod:`song.datasets.scenes.furniture`);
- **materials**: floors by region and venue (or the source's own, e.g. ProcTHOR's), wall paint by
  venue (or the source's colour), a white ceiling.

What only the source knows (openings, its materials, its ceiling height) travels as
:class:`DressingHints`, stored in the USD proxy's layer metadata so that ``song scenes splat`` can
rebuild the same scene later from the package alone.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

import numpy as np

from song.datasets.scenes.clutter import source_items, surface_items, wall_decor
from song.datasets.scenes.furniture import Part, object_frame, object_parts
from song.datasets.scenes.materials import floor_material, wall_material
from song.datasets.scenes.model import SemanticMap
from song.datasets.scenes.occupancy import OccupancyGrid
from song.geometry.freespace import clearance_field

CEILING_HEIGHT_M = 2.6  # default wall height when the source gives none
DOOR_HEIGHT_M = 2.1  # default top of an opening
TRIM_M = 0.05  # width of the trim around an opening
HANGING_MIN_M = 0.15  # objects whose bottom is higher than this hang (their parts are lifted)
DOOR_LEAF_M = 0.04  # thickness of the closed door drawn outside an entrance
PASSAGE_CATEGORIES = ("entrance", "door")  # objects that are openings, not obstacles


@dataclass(frozen=True)
class Opening:
    """A doorway: the segment ``a``–``b`` (m) along the wall's centre line, open from the floor to ``z_top``."""

    a: tuple[float, float]
    b: tuple[float, float]
    z_top: float = DOOR_HEIGHT_M
    thickness: float = 0.1


@dataclass(frozen=True)
class Window:
    """A window: the segment ``a``–``b`` (m) along a wall's centre line, glazed from ``z0`` to ``z1``."""

    a: tuple[float, float]
    b: tuple[float, float]
    z0: float
    z1: float


@dataclass(frozen=True)
class Item:
    """A source's small object standing on another or hanging (ProcTHOR's ``children[]``): an oriented box, m."""

    kind: str
    centre: tuple[float, float]
    yaw: float
    half: tuple[float, float]
    z0: float
    z1: float


@dataclass(frozen=True)
class DressingHints:
    """What a scene's source knows beyond its package files (stored in the USD proxy's layer metadata).

    Attributes:
        openings: doorways (lintels and trims are drawn above and around them).
        floor_materials: region id → floor material.
        wall_material: a material name or ``"paint:#rrggbb"`` for every wall.
        ceiling_height_m: wall height, m.
        seed: the dressing seed (furniture variants, textures, sample jitter).
        windows: the source's windows (ProcTHOR's); None: windows by rule on exterior walls
            (:func:`song.datasets.scenes.lights.rule_windows`).
        items: the source's small objects on other objects (:mod:`song.datasets.scenes.clutter`).
        clutter: dress the scene with clutter (items on tops and shelves, pictures and signs).
    """

    openings: tuple[Opening, ...] = ()
    floor_materials: dict[str, str] = field(default_factory=dict)
    wall_material: str | None = None
    ceiling_height_m: float | None = None
    seed: int = 0
    windows: tuple[Window, ...] | None = None
    items: tuple[Item, ...] = ()
    clutter: bool = True

    def to_json(self) -> str:
        """Canonical JSON text."""
        return json.dumps(asdict(self), sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> DressingHints:
        """Inverse of :meth:`to_json`."""
        data = json.loads(text)
        openings = tuple(
            Opening(tuple(o["a"]), tuple(o["b"]), float(o["z_top"]), float(o["thickness"]))
            for o in data.get("openings", [])
        )
        return cls(
            openings=openings,
            floor_materials=dict(data.get("floor_materials", {})),
            wall_material=data.get("wall_material"),
            ceiling_height_m=data.get("ceiling_height_m"),
            seed=int(data.get("seed", 0)),
            clutter=bool(data.get("clutter", True)),
            windows=None
            if data.get("windows") is None
            else tuple(Window(tuple(w["a"]), tuple(w["b"]), float(w["z0"]), float(w["z1"])) for w in data["windows"]),
            items=tuple(
                Item(
                    str(i["kind"]),
                    tuple(i["centre"]),
                    float(i["yaw"]),
                    tuple(i["half"]),
                    float(i["z0"]),
                    float(i["z1"]),
                )
                for i in data.get("items", [])
            ),
        )


@dataclass
class Dressing:
    """The visible structure of one scene (see the module docstring).

    Attributes:
        grid: the occupancy grid.
        venue: venue type.
        walls: wall polygons (shapely), world metres.
        wall_mask: (rows, cols) bool occupied cells not covered by an object.
        floor_mask: (rows, cols) bool cells that are free or under an object.
        ceiling_height: m.
        parts: furniture, lintels and trims.
        regions: (polygon, floor material) per region; ``default_floor`` elsewhere.
        wall_material: the wall paint.
        seed: texture seed.
    """

    grid: OccupancyGrid
    venue: str
    walls: list
    wall_mask: np.ndarray
    floor_mask: np.ndarray
    ceiling_height: float
    parts: list[Part]
    regions: list[tuple[object, str]]
    default_floor: str
    wall_material: str
    seed: int

    def floor_materials_at(self, xy: np.ndarray) -> tuple[list[str], np.ndarray]:
        """Floor materials at points (N, 2) as ``(names, index)``: ``names[index[i]]`` is point i's.

        A point takes the material of the first region containing it, else the default floor.
        """
        from shapely import contains_xy

        names = [self.default_floor] + [material for _, material in self.regions]
        index = np.zeros(len(xy), dtype=np.int64)
        unset = np.ones(len(xy), dtype=bool)
        for k, (polygon, _) in enumerate(self.regions):
            inside = unset & contains_xy(polygon, xy[:, 0], xy[:, 1])
            index[inside] = k + 1
            unset &= ~inside
        return names, index


def object_mask(smap: SemanticMap, grid: OccupancyGrid) -> np.ndarray:
    """(rows, cols) bool cells under an obstacle object's footprint (openings excluded)."""
    from song.datasets.scenes.raster import Rasterizer

    x0, y0 = grid.origin
    raster = Rasterizer(
        (x0, y0), (x0 + grid.shape[1] * grid.resolution, y0 + grid.shape[0] * grid.resolution), grid.resolution, fill=0
    )
    for obj in smap.objects:
        if obj.category not in PASSAGE_CATEGORIES:
            raster.polygon(np.asarray(obj.footprint), 255)
    return raster.cells[: grid.shape[0], : grid.shape[1]] == 255


def _wall_polygons(wall_mask: np.ndarray, grid: OccupancyGrid) -> list:
    from shapely.geometry.polygon import orient

    from song.geometry.navmesh import trace_legal

    polys = trace_legal(wall_mask, grid.resolution, grid.origin)
    out = []
    for poly in polys:
        simple = poly.simplify(0.5 * grid.resolution, preserve_topology=True)
        for part in getattr(simple, "geoms", [simple]):
            if part.geom_type == "Polygon" and part.area > grid.resolution**2:
                out.append(orient(part, 1.0))
    return out


def _wall_side(footprint: np.ndarray, room: np.ndarray, grid: OccupancyGrid) -> float:
    """+1 when the footprint rectangle's +y side has more free room in front of it than its −y side."""
    frame = object_frame(footprint, 1.0)
    probe = frame.hy + 0.25
    samples = np.array([frame.centre + probe * frame.ay, frame.centre - probe * frame.ay])
    rc = grid.to_cell(samples)
    rows, cols = room.shape
    vals = [room[r, c] if 0 <= r < rows and 0 <= c < cols else 0.0 for r, c in rc]
    return 1.0 if vals[0] >= vals[1] else -1.0


def opening_parts(index: int, opening: Opening, ceiling: float) -> list[Part]:
    """A lintel from the opening's top to the ceiling, and a trim (jambs and header) around it."""
    a, b = np.asarray(opening.a, float), np.asarray(opening.b, float)
    d = b - a
    length = float(np.linalg.norm(d))
    if length < 1e-6:
        return []
    yaw = float(np.arctan2(d[1], d[0]))
    centre = (a + b) / 2
    half_t = opening.thickness / 2
    top = min(opening.z_top, ceiling - 0.02)
    name = f"opening_{index}"
    parts = [
        Part(f"{name}/lintel", "lintel", "box", tuple(centre), yaw, (length / 2, half_t), top, ceiling, "plaster_white")
    ]
    trim_h = half_t + 0.01
    u = d / length
    for k, end in enumerate((a + u * TRIM_M / 2, b - u * TRIM_M / 2)):
        parts.append(
            Part(
                f"{name}/jamb{k}",
                "frame",
                "box",
                tuple(end),
                yaw,
                (TRIM_M / 2, trim_h),
                0.0,
                top,
                "wood_light",
                ("bottom",),
            )
        )
    parts.append(
        Part(
            f"{name}/header", "frame", "box", tuple(centre), yaw, (length / 2, trim_h), top - TRIM_M, top, "wood_light"
        )
    )
    return parts


def _outside_side(opening: Opening, floor_mask: np.ndarray, grid: OccupancyGrid) -> float:
    """+1 / −1 when the opening's left / right side (of a→b) has no floor (an entrance), else 0."""
    a, b = np.asarray(opening.a, float), np.asarray(opening.b, float)
    d = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
    left = np.array([-d[1], d[0]])
    reach = opening.thickness / 2 + 2 * grid.resolution
    rows, cols = floor_mask.shape
    floor = []
    for side in (1.0, -1.0):
        r, c = grid.to_cell(((a + b) / 2 + side * reach * left)[None])[0]
        floor.append(bool(0 <= r < rows and 0 <= c < cols and floor_mask[r, c]))
    if floor[0] == floor[1]:
        return 0.0
    return 1.0 if not floor[0] else -1.0


def door_leaf(index: int, opening: Opening, side: float) -> Part:
    """A closed door just outside an entrance (the ``door`` group: seen, not an obstacle of the map)."""
    a, b = np.asarray(opening.a, float), np.asarray(opening.b, float)
    d = b - a
    length = float(np.linalg.norm(d))
    left = np.array([-d[1], d[0]]) / length
    centre = (a + b) / 2 + side * (opening.thickness / 2 + DOOR_LEAF_M / 2) * left
    yaw = float(np.arctan2(d[1], d[0]))
    return Part(f"opening_{index}/door", "door", "box", tuple(centre), yaw, (length / 2, DOOR_LEAF_M / 2), 0.0,
                opening.z_top, "door_panel", ("bottom",))  # fmt: skip


def build_dressing(smap: SemanticMap, grid: OccupancyGrid, hints: DressingHints | None = None) -> Dressing:
    """The dressing of a scene (see the module docstring); deterministic in its inputs."""
    from shapely.geometry import Polygon

    hints = hints or DressingHints()
    seed = hints.seed
    venue = smap.venue_type
    under_objects = object_mask(smap, grid)
    wall_mask = (grid.cells != 255) & ~under_objects
    floor_mask = grid.free | under_objects
    ceiling = float(hints.ceiling_height_m or CEILING_HEIGHT_M)
    room = clearance_field(grid.free, grid.resolution)
    parts: list[Part] = []
    region_types = {r.id: r.type for r in smap.regions}
    for obj in smap.objects:
        footprint = np.asarray(obj.footprint, dtype=np.float64)
        frame = object_frame(footprint, _wall_side(footprint, room, grid))
        lift = obj.z_min if obj.z_min > HANGING_MIN_M else 0.0
        own = []
        for part in object_parts(obj.id, obj.label, obj.category, frame, obj.z_max - lift, venue, seed):
            if lift:
                part = Part(part.name, part.group, part.kind, part.centre, part.yaw, part.half, part.z0 + lift,
                            part.z1 + lift, part.material, tuple(h for h in part.hidden if h != "bottom"))  # fmt: skip
            own.append(part)
        region_type = region_types.get(obj.region or "", "")
        parts += surface_items(obj.id, obj.label, obj.category, region_type, own, venue, seed) if hints.clutter else own
    for index, opening in enumerate(hints.openings):
        parts += opening_parts(index, opening, ceiling)
        side = _outside_side(opening, floor_mask, grid)
        if side:  # an entrance: close it, or the camera would look out into the void
            parts.append(door_leaf(index, opening, side))
    default_floor = floor_material(None, venue)
    regions = [
        (Polygon(region.polygon), hints.floor_materials.get(region.id) or floor_material(region.type, venue))
        for region in smap.regions
    ]
    dressing = Dressing(
        grid=grid,
        venue=venue,
        walls=_wall_polygons(wall_mask, grid),
        wall_mask=wall_mask,
        floor_mask=floor_mask,
        ceiling_height=ceiling,
        parts=parts,
        regions=regions,
        default_floor=default_floor,
        wall_material=hints.wall_material or wall_material(venue),
        seed=seed,
    )
    if hints.clutter:
        if hints.windows is None:
            from song.datasets.scenes.lights import rule_windows

            windows = [_light_segment(light) for light in rule_windows(dressing, hints.openings)]
        else:
            windows = [(w.a, w.b) for w in hints.windows]
        # a source with its own small objects (ProcTHOR's paintings among them) gets no pictures by rule
        decor = source_items(hints.items) if hints.items else wall_decor(dressing, hints.openings, windows, seed)
        dressing.parts += decor
    return dressing


def _light_segment(light) -> tuple[np.ndarray, np.ndarray]:
    """The wall segment a window light covers."""
    u, _, _ = light.frame()
    c = np.asarray(light.position[:2])
    return c - u[:2] * light.size[0] / 2, c + u[:2] * light.size[0] / 2
