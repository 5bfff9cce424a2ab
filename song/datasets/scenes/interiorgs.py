"""InteriorGS raw folders → scene packages.

The dataset is gated, so this reads what its public descriptions document, and every frame
assumption lives in :data:`FRAME` and :func:`interiorgs_to_world` (tested):

- ``occupancy.png`` (top-down, 255 free, 0 occupied, other values unknown) with ``occupancy.json``
  ``{"scale": metres per pixel, "min": [x_min, y_min], "max": [x_max, y_max]}`` (``lower``/``upper``
  accepted as spellings of ``min``/``max``); image row 0 is the ``y_max`` edge (north-up).
- ``labels.json``: a list of ``{"ins_id", "label", "bounding_box": 8 corners}`` (corners as
  ``[x, y, z]`` or ``{"x", "y", "z"}``); the footprint is the convex hull of the corners in x-y.
- ``structure.json``: ``{"rooms": [{"room_type" | "label", "profile": [[x, y], ...]}]}``.
- ``3dgs_compressed.ply`` (optional) is copied as is.
World frame: metres, Z up (:data:`FRAME`); objects whose bottom is above ``FLOOR_OBJECT_MAX_BOTTOM_M``
(wall decorations, ceiling lamps) are labelled but not rasterised.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np

from song.datasets.scenes.model import OccupancySpec, Region, SceneObject, SemanticMap
from song.datasets.scenes.package import GAUSSIANS, write_scene_package
from song.datasets.scenes.procthor import ImportResult
from song.errors import SceneError, SongError

FRAME = {"units": "m", "up": "z", "image_row0": "y_max"}
FLOOR_OBJECT_MAX_BOTTOM_M = 0.15


def interiorgs_to_world(points: np.ndarray) -> np.ndarray:
    """InteriorGS points (..., 3) → SONG world (..., 3). Both are metres, Z up: the identity (assumed)."""
    return np.asarray(points, dtype=np.float64)


def _read_json(path: Path, what: str):
    if not path.is_file():
        raise SceneError(path, "", f"{what} is missing")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise SceneError(path, "", f"not valid JSON: {exc}") from exc


def _corners(box, path: Path, index: int) -> np.ndarray:
    try:
        pts = np.array([[c["x"], c["y"], c["z"]] if isinstance(c, dict) else c for c in box], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise SceneError(path, f"[{index}].bounding_box", f"expected 8 corners: {exc}") from exc
    if pts.shape != (8, 3) or not np.isfinite(pts).all():
        raise SceneError(path, f"[{index}].bounding_box", "expected 8 finite [x, y, z] corners")
    return interiorgs_to_world(pts)


def convert_folder(src: Path, scene_id: str, out_dir: Path) -> Path:
    """One InteriorGS folder → ``out_dir/scene_id``."""
    import cv2
    from shapely.geometry import MultiPoint, Point, Polygon

    meta = _read_json(src / "occupancy.json", "occupancy metadata")
    lo, hi = meta.get("min", meta.get("lower")), meta.get("max", meta.get("upper"))
    if lo is None or hi is None or "scale" not in meta:
        raise SceneError(src / "occupancy.json", "scale/min/max", "expected scale, min and max")
    image = cv2.imread(str(src / "occupancy.png"), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise SceneError(src / "occupancy.png", "", "missing or not a readable PNG")
    cells = np.where(image >= 250, 255, np.where(image <= 5, 0, 127)).astype(np.uint8)
    res = float(meta["scale"])
    origin = (float(lo[0]), float(lo[1]))
    bounds = (origin[0], origin[1], origin[0] + cells.shape[1] * res, origin[1] + cells.shape[0] * res)
    structure = _read_json(src / "structure.json", "structure")
    regions = []
    for index, room in enumerate(structure.get("rooms", [])):
        kind = re.sub(r"[^a-z0-9]+", "_", str(room.get("room_type", room.get("label", "room"))).lower()).strip("_")
        regions.append(
            Region(
                id=f"{kind}_{index + 1}",
                type=kind,
                name=kind.replace("_", " "),
                polygon=[tuple(p[:2]) for p in room["profile"]],
            )
        )
    shapes = {r.id: Polygon(r.polygon) for r in regions}
    labels_path = src / "labels.json"
    labels = _read_json(labels_path, "labels")
    objects, counts = [], {}
    for index, item in enumerate(labels):
        corners = _corners(item.get("bounding_box"), labels_path, index)
        hull = MultiPoint([tuple(p) for p in corners[:, :2]]).convex_hull
        if hull.area < 1e-4:
            continue
        label = re.sub(r"[^a-z0-9]+", "_", str(item.get("label", "object")).lower()).strip("_") or "object"
        counts[label] = counts.get(label, 0) + 1
        centre = hull.centroid
        region = next((rid for rid, s in shapes.items() if s.contains(Point(centre.x, centre.y))), None)
        footprint = [tuple(np.round(p, 4)) for p in np.asarray(hull.exterior.coords)[:-1]]
        objects.append(
            SceneObject(
                id=f"{label}_{counts[label]}",
                label=label.replace("_", " "),
                category="furniture",
                footprint=footprint,
                z_min=float(corners[:, 2].min()),
                z_max=float(corners[:, 2].max()),
                region=region,
            )
        )
    smap = SemanticMap(
        scene_id=scene_id,
        venue_type="home",
        source="interiorgs",
        licence="InteriorGS licence (see source)",
        bounds=bounds,
        occupancy=OccupancySpec(resolution=res, origin=origin),
        regions=regions,
        objects=objects,
    )
    root = write_scene_package(out_dir / scene_id, smap, cells)
    if (src / GAUSSIANS).is_file():
        shutil.copyfile(src / GAUSSIANS, root / GAUSSIANS)
    return root


def import_interiorgs(src: str | Path, out_dir: str | Path) -> list[ImportResult]:
    """Import one InteriorGS folder or a folder of them; a bad scene fails alone."""
    src, out_dir = Path(src), Path(out_dir)
    folders = [src] if (src / "labels.json").exists() else sorted(p for p in src.iterdir() if p.is_dir())
    results = []
    for folder in folders:
        scene_id = f"interiorgs_{re.sub(r'[^A-Za-z0-9_.-]', '_', folder.name)}"
        try:
            results.append(ImportResult(scene_id, convert_folder(folder, scene_id, out_dir)))
        except SongError as exc:
            results.append(ImportResult(scene_id, None, str(exc)))
        except (KeyError, TypeError, ValueError) as exc:
            results.append(ImportResult(scene_id, None, f"{folder}: malformed InteriorGS folder: {exc}"))
    return results
