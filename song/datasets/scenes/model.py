"""Pydantic model of ``semantic_map.json`` (format "song.semantic_map", version 1).

Structural checks (types, finiteness, polygon shape) live here; checks that need the occupancy image
or the other files live in :mod:`song.datasets.scenes.package`.
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from song.util import SAFE_ID

FORMAT_NAME = "song.semantic_map"
FORMAT_VERSION = 1
VENUE_TYPES = (
    "office",
    "lobby",
    "home",
    "clinic",
    "shop",
    "restaurant",
    "library",
    "hotel",
    "school",
    "station",
    "museum",
    "other",
)

Point2 = tuple[float, float]


def _check_point(point: Point2) -> Point2:
    if not all(math.isfinite(v) for v in point):
        raise ValueError("coordinates must be finite numbers")
    return point


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class VersionedFile(_Model):
    """A JSON file's top level with ``format`` and ``version`` checked against the class's own."""

    format_name: ClassVar[str]
    format_version: ClassVar[int]

    @field_validator("format", check_fields=False)
    @classmethod
    def _format(cls, value: str) -> str:
        if value != cls.format_name:
            raise ValueError(f"expected '{cls.format_name}'")
        return value

    @field_validator("version", check_fields=False)
    @classmethod
    def _version(cls, value: int) -> int:
        if value != cls.format_version:
            raise ValueError(f"unsupported version {value}; this release reads version {cls.format_version}")
        return value


class Frame(_Model):
    """Metric frame of the package: metres, Z up."""

    units: Literal["m"] = "m"
    up: Literal["z"] = "z"


class OccupancySpec(_Model):
    """Where the occupancy image lies in the world.

    Cell (row r, col c) covers x = x_min + (c + ½)·res, y = y_min + (rows − 1 − r + ½)·res.
    """

    path: str = "occupancy.png"
    resolution: float = Field(..., description="metres per cell, in [0.01, 0.5]")
    origin: Point2 = Field(..., description="[x_min, y_min] of the image's lower-left corner, m")

    @field_validator("resolution")
    @classmethod
    def _resolution(cls, value: float) -> float:
        if not math.isfinite(value) or not 0.01 <= value <= 0.5:
            raise ValueError("resolution must be a finite number in [0.01, 0.5] m per cell")
        return value

    @field_validator("origin")
    @classmethod
    def _origin(cls, value: Point2) -> Point2:
        return _check_point(value)

    @field_validator("path")
    @classmethod
    def _path(cls, value: str) -> str:
        if "/" in value or "\\" in value or value in ("", ".", ".."):
            raise ValueError("path must be a file name inside the package")
        return value


def _check_polygon(points: list[Point2], what: str) -> list[Point2]:
    """Finite, ≥ 3 distinct vertices, non-zero area, simple; an explicit closing vertex is dropped."""
    for point in points:
        _check_point(point)
    if len(points) >= 2 and tuple(points[0]) == tuple(points[-1]):
        points = points[:-1]
    if len(points) < 3:
        raise ValueError(f"{what} needs at least 3 distinct vertices")
    from shapely.geometry import Polygon

    polygon = Polygon(points)
    centred = [(x - points[0][0], y - points[0][1]) for x, y in points]
    if all(abs(ax * by - ay * bx) <= 1e-12 for (ax, ay), (bx, by) in zip(centred, centred[1:], strict=False)):
        raise ValueError(f"{what} is degenerate (zero area)")
    if not polygon.exterior.is_simple:
        raise ValueError(f"{what} is self-intersecting")
    if polygon.area <= 1e-9:
        raise ValueError(f"{what} is degenerate (zero area)")
    if not polygon.is_valid:
        raise ValueError(f"{what} is self-intersecting")
    return [tuple(p) for p in points]


class Region(_Model):
    """A room or functional area."""

    id: str
    type: str
    name: str | None = None
    polygon: list[Point2]

    @field_validator("polygon")
    @classmethod
    def _polygon(cls, value: list[Point2]) -> list[Point2]:
        return _check_polygon(value, "polygon")


class SceneObject(_Model):
    """A named object; ``id`` is the handle the LLM prompts refer to (``reception_desk_1``)."""

    id: str
    label: str
    category: str
    footprint: list[Point2]
    z_min: float = 0.0
    z_max: float = 1.0
    region: str | None = None

    @field_validator("footprint")
    @classmethod
    def _footprint(cls, value: list[Point2]) -> list[Point2]:
        value = _check_polygon(value, "footprint")
        from shapely.geometry import Polygon
        from shapely.geometry.polygon import orient

        return [tuple(p) for p in orient(Polygon(value), 1.0).exterior.coords[:-1]]

    @field_validator("z_min", "z_max")
    @classmethod
    def _finite(cls, value: float) -> float:
        if not math.isfinite(value):
            raise ValueError("must be a finite number")
        return value


class SemanticMap(VersionedFile):
    """Top level of ``semantic_map.json``."""

    format_name: ClassVar[str] = FORMAT_NAME
    format_version: ClassVar[int] = FORMAT_VERSION

    format: str = FORMAT_NAME
    version: int = FORMAT_VERSION
    scene_id: str
    venue_type: str
    source: str = "procedural"
    name: str | None = None
    licence: str | None = None
    frame: Frame = Frame()
    bounds: tuple[float, float, float, float] = Field(
        ..., description="[x_min, y_min, x_max, y_max] of the scene, m; the occupancy image covers it"
    )
    occupancy: OccupancySpec
    regions: list[Region] = []
    objects: list[SceneObject] = []

    @field_validator("bounds")
    @classmethod
    def _bounds(cls, value: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        if not all(math.isfinite(v) for v in value):
            raise ValueError("coordinates must be finite numbers")
        if value[2] <= value[0] or value[3] <= value[1]:
            raise ValueError("expected x_max > x_min and y_max > y_min")
        return value

    @field_validator("scene_id")
    @classmethod
    def _scene_id(cls, value: str) -> str:
        if not SAFE_ID.fullmatch(value) or ".." in value:
            raise ValueError("scene id must be 1-128 of [A-Za-z0-9_.-], no path separators or '..'")
        return value

    def object_by_id(self) -> dict[str, SceneObject]:
        """Objects keyed by id."""
        return {obj.id: obj for obj in self.objects}
