"""Habitat scene assets: GLBs from a USD proxy or from an occupancy map, Y-up, deterministic."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import trimesh

from song.datasets.bench.habitat import WALL_HEIGHT_M, glb_bytes, occupancy_meshes
from song.datasets.bench.types import StaticMap


def _load(data: bytes) -> trimesh.Scene:
    return trimesh.load(io.BytesIO(data), file_type="glb", force="scene")


def test_occupancy_boxes_cover_exactly_the_blocked_cells() -> None:
    rng = np.random.default_rng(3)
    cells = np.where(rng.random((23, 31)) < 0.3, 0, 255).astype(np.uint8)
    cells[5, 7] = 127  # unknown counts as blocked
    static = StaticMap(cells=cells, resolution=0.1, origin=(-1.0, 2.0))
    meshes = occupancy_meshes(static)
    solids = [trimesh.Trimesh(m.vertices, m.faces, process=False) for m in meshes if m.name != "floor"]
    assert all(s.is_watertight for s in solids)
    blocked_area = (cells != 255).sum() * 0.01
    assert sum(s.volume for s in solids) == pytest.approx(blocked_area * WALL_HEIGHT_M, rel=1e-9)
    # every blocked cell centre lies in a box footprint, no free one does
    rows, cols = cells.shape
    r, c = np.mgrid[0:rows, 0:cols]
    centres = np.column_stack([-1.0 + (c.ravel() + 0.5) * 0.1, 2.0 + (rows - r.ravel() - 0.5) * 0.1])
    inside = np.zeros(len(centres), dtype=bool)
    for s in solids:
        lo, hi = s.bounds[0, :2], s.bounds[1, :2]
        inside |= ((centres > lo) & (centres < hi)).all(axis=1)
    np.testing.assert_array_equal(inside, cells.ravel() != 255)


def test_glb_is_y_up_and_deterministic() -> None:
    cells = np.full((20, 40), 255, np.uint8)
    cells[0], cells[:, 0] = 0, 0
    meshes = occupancy_meshes(StaticMap(cells=cells, resolution=0.1, origin=(0.0, 0.0)))
    data = glb_bytes(meshes)
    assert data == glb_bytes(meshes)
    lo, hi = _load(data).bounds
    np.testing.assert_allclose(lo, [0.0, 0.0, -2.0], atol=1e-6)  # (x, z, −y): y ∈ [0, 2] → z ∈ [−2, 0]
    np.testing.assert_allclose(hi, [4.0, WALL_HEIGHT_M, 0.0], atol=1e-6)


def test_glb_from_a_usd_proxy(tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from song.datasets.scenes.usd import ProxyBox, read_usd_proxy, write_usd_proxy

    path = tmp_path / "scene_flat.usda"
    write_usd_proxy(path, [ProxyBox("desk", np.array([[1, 1], [2, 1], [2, 1.5], [1, 1.5]]), 0.0, 0.75)])
    scene = _load(glb_bytes(read_usd_proxy(path)))
    np.testing.assert_allclose(scene.bounds, [[1.0, 0.0, -1.5], [2.0, 0.75, -1.0]], atol=1e-6)
    assert "desk" in scene.graph.nodes
