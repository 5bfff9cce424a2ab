"""USD proxy: Z-up metres stage, watertight outward prisms, deterministic text, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from song.datasets.scenes.usd import ProxyBox, read_usd_proxy, write_usd_proxy
from song.errors import FormatError

pytest.importorskip("pxr")


def test_round_trip_and_geometry(tmp_path: Path) -> None:
    boxes = [
        ProxyBox("wall|1", np.array([[0, 0], [4, 0], [4, 0.1], [0, 0.1]]), 0.0, 2.5),
        ProxyBox("3 desk", np.array([[1, 1], [2, 1], [2, 1.6], [1, 1.6]]), 0.0, 0.75),
        ProxyBox("3 desk", np.array([[3, 1], [3.5, 1], [3.5, 1.5], [3, 1.5]]), 0.0, 1.0),
    ]
    path = tmp_path / "scene_flat.usda"
    write_usd_proxy(path, boxes)
    text = path.read_text()
    assert 'upAxis = "Z"' in text and "metersPerUnit = 1" in text
    meshes = read_usd_proxy(path)
    assert [m.name for m in meshes] == ["wall_1", "_3_desk", "_3_desk_2"]
    for mesh, box in zip(meshes, boxes, strict=True):
        solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        assert solid.is_watertight
        area = float(np.abs(np.cross(box.footprint[1] - box.footprint[0], box.footprint[3] - box.footprint[0])))
        assert solid.volume == pytest.approx(area * (box.z_max - box.z_min), rel=1e-5)  # > 0: outward normals
    write_usd_proxy(tmp_path / "again.usda", boxes)
    assert (tmp_path / "again.usda").read_bytes() == path.read_bytes()


def test_bad_proxy_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "scene_flat.usda"
    bad.write_text('#usda 1.0\n(\n    upAxis = "Y"\n)\n')
    with pytest.raises(FormatError, match="upAxis"):
        read_usd_proxy(bad)
    with pytest.raises(FormatError, match="missing"):
        read_usd_proxy(tmp_path / "none.usda")
