"""Clutter: items stand on their tops without overlapping, pictures hang on walls clear of doors, the map is untouched."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Polygon
from shapely.ops import unary_union

from song.datasets.scenes import load_scene_package
from song.datasets.scenes.clutter import item_count
from song.datasets.scenes.dressing import DressingHints, build_dressing
from song.datasets.scenes.generate import generate_scene
from song.datasets.scenes.package import USD_PROXY
from song.datasets.scenes.usd import read_usd_dressing
from tests.conftest import SHARED_HOUSES, shared_file


def _footprint(part) -> Polygon:
    """The part's footprint (a rectangle; cylinders and ellipsoids by their bounding rectangle)."""
    c, s = math.cos(part.yaw), math.sin(part.yaw)
    hx, hy = part.half
    corners = [(x * hx, y * hy) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return Polygon([(part.centre[0] + c * x - s * y, part.centre[1] + s * x + c * y) for x, y in corners])


@pytest.fixture(scope="module", params=["office", "restaurant", "library"])
def dressed(request, tmp_path_factory):
    root = generate_scene(f"{request.param}_0001", request.param, 11, tmp_path_factory.mktemp("clutter"), splat=False)
    package = load_scene_package(root)
    hints = DressingHints.from_json(read_usd_dressing(root / USD_PROXY))
    return package, hints, build_dressing(package.semantic_map, package.occupancy, hints)


def test_items_stand_on_a_top_inside_it_and_apart(dressed) -> None:
    package, _, dressing = dressed
    items = [p for p in dressing.parts if p.group.startswith("item:") and not p.name.startswith("decor")]
    assert item_count(items) >= 20
    furniture = [p for p in dressing.parts if not p.group.startswith("item:") and p.group not in ("lintel", "frame")]
    by_height: dict[float, list] = {}
    for item in items:
        if item.name.endswith("/leaves"):  # on its pot
            continue
        if item.z0 < 0.01:  # under a desk: inside the desk's footprint, on cells the map already blocks
            owner = item.name.split("/")[0]
            desk = Polygon(next(o.footprint for o in package.semantic_map.objects if o.id == owner))
            assert desk.buffer(1e-6).contains(_footprint(item)), item.name
            continue
        support = [p for p in furniture if abs(p.z1 - item.z0) < 1e-6 and p.kind == "box"]
        assert support, f"{item.name} floats"
        assert any(_footprint(p).buffer(1e-6).contains(_footprint(item).centroid) for p in support), item.name
        by_height.setdefault(round(item.z0, 4), []).append(item)
    # items placed on one top do not overlap (shelf rows abut by construction; plants overhang their pots)
    for group in by_height.values():
        placed = [p for p in group if "/item" in p.name and "/items" not in p.name and p.kind != "ellipsoid"]
        for i, a in enumerate(placed):
            for b in placed[i + 1 :]:
                if (
                    a.name.split("/")[0] == b.name.split("/")[0]
                    and a.name.rsplit("/", 1)[0] != b.name.rsplit("/", 1)[0]
                ):
                    assert _footprint(a).intersection(_footprint(b)).area < 1e-6, (a.name, b.name)


def test_clutter_leaves_the_map_and_the_walkways_alone(dressed) -> None:
    package, hints, dressing = dressed
    bare = build_dressing(package.semantic_map, package.occupancy, dataclasses.replace(hints, clutter=False))
    assert np.array_equal(bare.floor_mask, dressing.floor_mask) and np.array_equal(bare.wall_mask, dressing.wall_mask)
    grid = package.occupancy
    objects = unary_union([Polygon(o.footprint) for o in package.semantic_map.objects])
    for part in dressing.parts:
        if not part.group.startswith("item:") or part.z0 > 1.0 or part.name.startswith("decor"):
            continue
        # anything low enough to trip over stands within an object's footprint: walkways stay free
        assert objects.buffer(0.05).contains(_footprint(part)), part.name
    decor = [p for p in dressing.parts if p.name.startswith("decor")]
    for part in decor:
        assert part.z0 > 1.0  # above a walker's hips
        centre = np.array(part.centre)
        for opening in hints.openings:
            a, b = np.asarray(opening.a), np.asarray(opening.b)
            t = np.clip((centre - a) @ (b - a) / max((b - a) @ (b - a), 1e-12), 0, 1)
            assert np.linalg.norm(a + t * (b - a) - centre) > 0.8, part.name  # never over or beside a door
        # on a wall: within a few centimetres of an occupied cell
        rc = grid.to_cell(np.array([part.centre]))[0]
        window = grid.cells[max(rc[0] - 2, 0) : rc[0] + 3, max(rc[1] - 2, 0) : rc[1] + 3]
        assert (window == 0).any(), part.name
    if dressing.venue in ("office", "restaurant", "library"):
        assert decor, "no pictures on the walls"


def test_procthor_children_become_items(tmp_path: Path) -> None:
    from song.datasets.scenes.procthor import import_procthor

    house = shared_file(SHARED_HOUSES / "house_6.json")
    import_procthor(house, tmp_path, splat=False, assets=SHARED_HOUSES / "asset_bboxes.json")
    root = next(p for p in tmp_path.iterdir() if p.is_dir())
    hints = DressingHints.from_json(read_usd_dressing(root / USD_PROXY))
    assert len(hints.items) > 30 and hints.windows
    kinds = {item.kind for item in hints.items}
    assert {"book", "laptop"} & kinds
    package = load_scene_package(root)
    dressing = build_dressing(package.semantic_map, package.occupancy, hints)
    assert item_count([p for p in dressing.parts if p.name.startswith("item_")]) == len(hints.items)
