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


def _gltf_validator() -> Path:
    """Khronos' glTF validator from npm, installed once into a cache folder (the test's own environment)."""
    import shutil
    import subprocess

    npm = shutil.which("npm")
    if npm is None or shutil.which("node") is None:
        pytest.skip("node and npm are needed to install Khronos' gltf-validator")
    cache = Path.home() / ".cache" / "song-tests" / "gltf-validator"
    if not (cache / "node_modules" / "gltf-validator").is_dir():
        cache.mkdir(parents=True, exist_ok=True)
        done = subprocess.run([npm, "install", "--silent", "--prefix", str(cache), "gltf-validator@2.0.0-dev.3.10"],
                              capture_output=True, text=True, timeout=300)  # fmt: skip
        if done.returncode:
            pytest.skip(f"npm could not install gltf-validator: {done.stderr.strip()[-200:]}")
    return cache


def test_a_scene_glb_passes_the_khronos_validator_with_materials_and_normals(tmp_path: Path) -> None:
    import json
    import struct
    import subprocess

    pytest.importorskip("pxr")
    from song.datasets.scenes.generate import generate_scene
    from song.datasets.scenes.usd import read_usd_proxy, read_usd_surfaces

    root = generate_scene("office_0000", "office", 3, tmp_path / "s", True, 0.08)
    usd = root / "scene_flat.usda"
    data = glb_bytes([*read_usd_proxy(usd), *read_usd_surfaces(usd)])
    (tmp_path / "scene.glb").write_bytes(data)
    cache = _gltf_validator()
    script = (
        "const v=require('gltf-validator');const fs=require('fs');"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[1])))"
        ".then(r=>console.log(JSON.stringify(r.issues))).catch(e=>{console.error(e);process.exit(2)});"
    )
    done = subprocess.run(["node", "-e", script, str(tmp_path / "scene.glb")], capture_output=True, text=True,
                          cwd=cache, env={"NODE_PATH": str(cache / "node_modules"), "PATH": "/usr/bin:/bin"})  # fmt: skip
    assert done.returncode == 0, done.stderr
    issues = json.loads(done.stdout)
    assert issues["numErrors"] == 0, issues["messages"][:5]
    length = struct.unpack_from("<I", data, 12)[0]
    gltf = json.loads(data[20 : 20 + length])
    primitives = [p for m in gltf["meshes"] for p in m["primitives"]]
    assert all("NORMAL" in p["attributes"] and "material" in p for p in primitives)
    colours = {tuple(m["pbrMetallicRoughness"]["baseColorFactor"]) for m in gltf["materials"]}
    assert len(colours) >= 5  # walls, floors, wood, fabric, metal: the proxy's albedos, not one grey
