"""Scene packages: load, validate and write.

A package is a folder ``<scene_id>/`` with ``semantic_map.json`` and ``occupancy.png`` (required),
``3dgs_compressed.ply``, ``scene_flat.usda`` and ``lights.json`` (optional). :func:`load_scene_package` runs every
check and raises :class:`SceneError` with one line naming the file and the field.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from song.datasets.limits import load_json
from song.datasets.scenes.model import SemanticMap
from song.datasets.scenes.occupancy import OccupancyGrid, encode_occupancy_png, read_occupancy_png
from song.errors import FormatError, SceneError
from song.util import sha256_file, write_bytes_atomic, write_text_atomic

SEMANTIC_MAP = "semantic_map.json"
OCCUPANCY = "occupancy.png"
GAUSSIANS = "3dgs_compressed.ply"
USD_PROXY = "scene_flat.usda"
LIGHTS = "lights.json"
PACKAGE_FILES = (SEMANTIC_MAP, OCCUPANCY, GAUSSIANS, USD_PROXY, LIGHTS)
BOUNDS_TOLERANCE_CELLS = 0.5  # image extent may differ from bounds by rounding to whole cells


@dataclass(frozen=True)
class ScenePackage:
    """A validated scene package.

    Attributes:
        root: the package folder.
        semantic_map: the parsed ``semantic_map.json``.
        occupancy: the occupancy grid placed in the world.
    """

    root: Path
    semantic_map: SemanticMap
    occupancy: OccupancyGrid

    @property
    def scene_id(self) -> str:
        """The scene id from the semantic map."""
        return self.semantic_map.scene_id

    @property
    def gaussians_path(self) -> Path | None:
        """The Gaussian PLY, or None when the package has none."""
        path = self.root / GAUSSIANS
        return path if path.is_file() else None

    @property
    def usd_path(self) -> Path | None:
        """The USD proxy, or None when the package has none."""
        path = self.root / USD_PROXY
        return path if path.is_file() else None

    def content_hash(self) -> dict[str, str]:
        """sha256 of every present package file, keyed by file name (the stage chain's input hash)."""
        return {name: sha256_file(self.root / name) for name in PACKAGE_FILES if (self.root / name).is_file()}


def _field_path(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def parse_semantic_map(path: Path) -> SemanticMap:
    """Read and structurally validate ``semantic_map.json``."""
    if not path.is_file():
        raise SceneError(path, "", "file is missing")
    data = load_json(path, error=SceneError)
    if not isinstance(data, dict):
        raise SceneError(path, "", "expected a JSON object at the top level")
    try:
        return SemanticMap.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        message = first["msg"].removeprefix("Value error, ")
        raise SceneError(path, _field_path(first["loc"]), message) from exc


def _largest_free_area_m2(grid: OccupancyGrid) -> float:
    from scipy import ndimage

    labels, count = ndimage.label(grid.free)
    if count == 0:
        return 0.0
    sizes = np.bincount(labels.ravel())[1:]
    return float(sizes.max()) * grid.resolution**2


def check_consistency(smap: SemanticMap, grid: OccupancyGrid, root: Path, min_free_area_m2: float = 4.0) -> None:
    """Checks that need the whole package: ids, bounds, image size, free space."""
    map_path = root / SEMANTIC_MAP
    seen: dict[str, str] = {}
    for kind, items in (("regions", smap.regions), ("objects", smap.objects)):
        for index, item in enumerate(items):
            if item.id in seen:
                raise SceneError(map_path, f"{kind}[{index}].id", f"duplicate id '{item.id}' (also in {seen[item.id]})")
            seen[item.id] = kind
    region_ids = {region.id for region in smap.regions}
    x0, y0, x1, y1 = smap.bounds
    slack = grid.resolution
    for kind, items, attr in (("regions", smap.regions, "polygon"), ("objects", smap.objects, "footprint")):
        for index, item in enumerate(items):
            pts = np.asarray(getattr(item, attr))
            if (
                (pts[:, 0] < x0 - slack).any()
                or (pts[:, 0] > x1 + slack).any()
                or ((pts[:, 1] < y0 - slack).any() or (pts[:, 1] > y1 + slack).any())
            ):
                raise SceneError(map_path, f"{kind}[{index}].{attr}", f"'{item.id}' lies outside the scene bounds")
    for index, obj in enumerate(smap.objects):
        if obj.region is not None and obj.region not in region_ids:
            raise SceneError(map_path, f"objects[{index}].region", f"unknown region '{obj.region}'")
        if obj.z_max < obj.z_min:
            raise SceneError(map_path, f"objects[{index}].z_max", "z_max is below z_min")
    rows, cols = grid.shape
    want_cols = (x1 - x0) / grid.resolution
    want_rows = (y1 - y0) / grid.resolution
    if abs(cols - want_cols) > BOUNDS_TOLERANCE_CELLS + 1e-6 or abs(rows - want_rows) > BOUNDS_TOLERANCE_CELLS + 1e-6:
        raise SceneError(
            root / smap.occupancy.path,
            "size",
            f"image is {cols}x{rows} cells but bounds/resolution need {want_cols:.1f}x{want_rows:.1f}",
        )
    if abs(smap.occupancy.origin[0] - x0) > slack or abs(smap.occupancy.origin[1] - y0) > slack:
        raise SceneError(map_path, "occupancy.origin", "origin must be the lower-left corner of bounds")
    values = np.unique(grid.cells)
    bad = set(values.tolist()) - {0, 127, 255}
    if bad:
        raise SceneError(root / smap.occupancy.path, "pixels", f"unexpected values {sorted(bad)[:5]}; use 0, 127, 255")
    area = _largest_free_area_m2(grid)
    if area < min_free_area_m2:
        raise SceneError(
            root / smap.occupancy.path,
            "free",
            f"largest free area is {area:.2f} m², need ≥ {min_free_area_m2} m²",
        )


def check_optional_files(root: Path) -> None:
    """Cheap checks of the optional files.

    The PLY's header, schema and body size (no decoding); the USD layer's text header and up axis (the
    full read is :func:`read_usd_proxy`).
    """
    from song.datasets.scenes.ply import check_gaussian_ply

    gaussians = root / GAUSSIANS
    if gaussians.exists():
        try:
            count = check_gaussian_ply(gaussians)
        except FormatError as exc:
            raise SceneError(exc.file, exc.field, exc.message) from exc
        if count == 0:
            raise SceneError(gaussians, "vertex", "holds no splats")
    usd = root / USD_PROXY
    if usd.exists():
        head = _usd_header(usd) if usd.is_file() else b""
        if not head.startswith(b"#usda "):
            raise SceneError(usd, "header", "not a USD text layer (expected '#usda 1.0' on the first line)")
        if b'upAxis = "Z"' not in head:
            raise SceneError(usd, "upAxis", 'layer metadata must say upAxis = "Z"')
    if (root / LIGHTS).exists():
        from song.datasets.scenes.lights import read_lights

        read_lights(root / LIGHTS)


def _usd_header(path: Path, limit: int = 8 << 20) -> bytes:
    """A text layer's first line and metadata block (up to the first line that is only ``)``)."""
    with path.open("rb") as f:
        head = f.read(limit)
    end = head.find(b"\n)")
    return head if end < 0 else head[:end]


def load_scene_package(root: str | Path, min_free_area_m2: float = 4.0) -> ScenePackage:
    """Load and fully validate a scene package folder.

    Raises:
        SceneError: one line naming the file and field of the first problem found.
    """
    root = Path(root)
    if not root.is_dir():
        raise SceneError(root, "", "scene package folder is missing")
    smap = parse_semantic_map(root / SEMANTIC_MAP)
    grid = read_occupancy_png(root / smap.occupancy.path, smap.occupancy.resolution, smap.occupancy.origin)
    check_consistency(smap, grid, root, min_free_area_m2)
    if smap.scene_id != root.name:
        raise SceneError(root / SEMANTIC_MAP, "scene_id", f"'{smap.scene_id}' does not match folder name '{root.name}'")
    check_optional_files(root)
    return ScenePackage(root=root, semantic_map=smap, occupancy=grid)


def write_scene_package(root: str | Path, smap: SemanticMap, cells: np.ndarray) -> Path:
    """Write ``semantic_map.json`` and ``occupancy.png`` atomically into ``root`` (created if needed).

    The optional Gaussian PLY and USD proxy are written by their own modules. JSON bytes are stable
    for the same content (sorted keys, fixed float repr), so the same seed gives identical files.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    payload = smap.model_dump(mode="json", exclude_none=True)
    write_text_atomic(root / SEMANTIC_MAP, json.dumps(payload, indent=1, sort_keys=True) + "\n")
    write_bytes_atomic(root / smap.occupancy.path, encode_occupancy_png(cells))
    return root


def find_scene_packages(folder: str | Path) -> list[Path]:
    """Sub-folders of ``folder`` that look like scene packages, sorted by name (or ``folder`` itself)."""
    folder = Path(folder)
    if (folder / SEMANTIC_MAP).is_file():
        return [folder]
    if not folder.is_dir():
        raise SceneError(folder, "", "scenes folder is missing")
    return sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
