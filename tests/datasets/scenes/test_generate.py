"""Procedural scenes: valid, connected at the pedestrian radius, realistic doors, all four files, deterministic."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from song.datasets.scenes import load_scene_package
from song.datasets.scenes.generate import VENUE_ORDER, generate_scenes
from song.datasets.scenes.package import PACKAGE_FILES
from song.datasets.scenes.ply import read_gaussian_ply
from song.datasets.scenes.usd import read_usd_proxy
from song.geometry.freespace import components, erode


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_every_venue_is_valid_connected_and_complete(tmp_path: Path) -> None:
    roots = generate_scenes(len(VENUE_ORDER), seed=3, out_dir=tmp_path / "a", spacing=0.07)
    assert {load_scene_package(r).semantic_map.venue_type for r in roots} == set(VENUE_ORDER)
    labels_by_venue = {}
    for root in roots:
        package = load_scene_package(root)
        assert all((root / name).is_file() for name in PACKAGE_FILES)
        grid = package.occupancy
        legal = erode(grid.free, grid.resolution, 0.25)
        _, parts = components(legal)
        assert parts == 1, f"{root.name}: walkable area split in {parts}"
        x0, y0, x1, y1 = package.semantic_map.bounds
        assert 6 <= x1 - x0 <= 40 and 6 <= y1 - y0 <= 30
        cloud = read_gaussian_ply(root / "3dgs_compressed.ply")
        assert 40_000 < len(cloud) < 400_000  # a quarter of the default density at twice the spacing
        assert (cloud.means[:, 2] > -0.05).all() and (cloud.means[:, 2] < 2.7).all()
        meshes = read_usd_proxy(root / "scene_flat.usda")
        assert len(meshes) >= len(package.semantic_map.objects) - 1  # every furniture box + walls
        labels_by_venue[package.semantic_map.venue_type] = {o.label for o in package.semantic_map.objects}
        assert (root / "3dgs_compressed.ply").stat().st_size < 20 * len(cloud)
    assert "reception desk" in labels_by_venue["office"] and "examination bed" in labels_by_venue["clinic"]
    assert labels_by_venue["library"] != labels_by_venue["restaurant"]


def test_doorways_have_realistic_widths(tmp_path: Path) -> None:
    from song.datasets.scenes import generate as gen

    for venue in VENUE_ORDER:
        for attempt in range(3):
            rng = np.random.default_rng(attempt)
            width, _, (cy0, cy1), rooms = gen._layout(venue, rng)
            assert 1.2 <= cy1 - cy0 <= 2.5  # corridor
            for room in rooms:
                assert 0.8 <= room.door[2] <= 2.5


def test_same_seed_identical_bytes(tmp_path: Path) -> None:
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        generate_scenes(3, seed=seed, out_dir=tmp_path / name, spacing=0.1)
    assert _files(tmp_path / "a") == _files(tmp_path / "b")
    assert _files(tmp_path / "a") != _files(tmp_path / "c")
