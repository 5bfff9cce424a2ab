"""USD proxy: Z-up metres stage, watertight outward prisms, deterministic text, errors."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from song.datasets.scenes.usd import ProxyBox, read_usd_proxy, write_usd_proxy
from song.errors import FormatError, MissingDependencyError

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


def _usda(body: str, up: str = "Z", mpu: str = "1") -> str:
    return (
        f'#usda 1.0\n(\n    metersPerUnit = {mpu}\n    upAxis = "{up}"\n)\n\n'
        f'def Xform "World"\n{{\n    def Scope "collision"\n    {{\n{body}\n    }}\n}}\n'
    )


QUAD = """        def Mesh "slab"
        {
            int[] faceVertexCounts = [4, 3]
            int[] faceVertexIndices = [0, 1, 2, 3, 0, 2, 4]
            point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0.5, 0.5, 1)]
        }
        def Xform "not_a_mesh"
        {
        }"""


def test_reader_triangulates_other_tools_meshes(tmp_path: Path) -> None:
    path = tmp_path / "scene_flat.usda"
    path.write_text(_usda(QUAD))
    (mesh,) = read_usd_proxy(path)  # the Xform child is skipped
    assert mesh.name == "slab" and mesh.vertices.shape == (5, 3) and mesh.vertices.dtype == np.float64
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 2, 4]])


@pytest.mark.parametrize(
    ("text", "field", "what"),
    [
        ("garbage {{{", "", "not a readable USD layer"),
        (_usda(QUAD, up="Y"), "upAxis", "expected 'Z'"),
        (_usda(QUAD, mpu="0.01"), "metersPerUnit", "expected 1"),
        (
            '#usda 1.0\n(\n    upAxis = "Z"\n    metersPerUnit = 1\n)\ndef Xform "World"\n{\n}\n',
            "/World/collision",
            "missing",
        ),
        (_usda(QUAD.replace("[0, 1, 2, 3, 0, 2, 4]", "[0, 1, 2, 3, 0, 2, 9]")), "slab.faceVertexIndices", "range"),
        (_usda(QUAD.replace("[4, 3]", "[4, 4]")), "slab.faceVertexCounts", "indices"),
    ],
    ids=["garbage", "y_up", "centimetres", "no_collision", "bad_index", "bad_counts"],
)
def test_bad_proxy_names_file_and_field(tmp_path: Path, text: str, field: str, what: str) -> None:
    path = tmp_path / "scene_flat.usda"
    path.write_text(text)
    with pytest.raises(FormatError) as info:
        read_usd_proxy(path)
    message = str(info.value)
    assert str(path) in message and field in message and what in message and "\n" not in message, message


def test_writer_rejects_bad_boxes_and_leaves_nothing(tmp_path: Path) -> None:
    flat = ProxyBox("flat", np.array([[0, 0], [1, 0], [1, 1], [0, 1]]), 1.0, 1.0)
    with pytest.raises(ValueError, match=r"boxes\[0\] 'flat'"):
        write_usd_proxy(tmp_path / "scene_flat.usda", [flat])
    nan = ProxyBox("nan", np.array([[0, 0], [np.nan, 0], [1, 1], [0, 1]]), 0.0, 1.0)
    with pytest.raises(ValueError, match="finite"):
        write_usd_proxy(tmp_path / "scene_flat.usda", [nan])
    write_usd_proxy(tmp_path / "scene_flat.usda", [])
    assert [p.name for p in tmp_path.iterdir()] == ["scene_flat.usda"]  # atomic: no temporary left
    assert read_usd_proxy(tmp_path / "scene_flat.usda") == []


def test_missing_usd_core_names_the_extra(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "pxr", None)  # import pxr now raises ImportError
    for call in (lambda: write_usd_proxy(tmp_path / "x.usda", []), lambda: read_usd_proxy(tmp_path / "x.usda")):
        with pytest.raises(MissingDependencyError) as info:
            call()
        assert info.value.module == "pxr" and info.value.extra == "usd" and "song[usd]" in str(info.value)


def _every_kind_of_prim():
    from song.datasets.scenes.lights import Light
    from song.datasets.scenes.usd import ProxyMesh

    tetra = ProxyMesh(
        "lamp base",
        np.array([[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [0, 0, 0.4]]),
        np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]),
        material="metal_steel",
        label="lamp",
        convex=True,
    )
    floor = ProxyMesh(
        "floor 0", np.array([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]]), np.array([[0, 1, 2], [0, 2, 3]])
    )
    solids = [
        ProxyBox("wall|1", np.array([[0, 0], [4, 0], [4, 0.1], [0, 0.1]]), 0.0, 2.5),
        tetra,
        ProxyMesh("bare", tetra.vertices + 1.0, tetra.faces),
        ProxyMesh("painted", tetra.vertices + 2.0, tetra.faces, material="paint:#a0b0c0", label="wall"),
    ]
    surfaces = [
        ProxyMesh("floor 0", floor.vertices, floor.faces, material="tiles_grey", label="floor"),
        ProxyMesh("ceiling", floor.vertices + [0, 0, 2.5], floor.faces[:, ::-1], material="metal_steel"),
    ]
    rooms = [ProxyMesh("room_office", floor.vertices, floor.faces, label="office")]
    lights = [
        Light(id="panel 0", kind="rect", role="ceiling", position=(1, 1, 2.49), size=(0.6, 1.2), power_w=40),
        Light(id="lamp", kind="point", role="lamp", position=(0.1, 0.1, 0.5), radius=0.05, power_w=7.5),
        Light(id="window", kind="rect", role="window", position=(0, 1.5, 1.4), normal=(1, 0, 0), u_axis=(0, 1, 0),
              size=(1.0, 1.2), colour=(0.9, 0.95, 1.1), power_w=120),
    ]  # fmt: skip
    return solids, surfaces, rooms, lights


@pytest.mark.parametrize("metadata", [False, True])
def test_the_written_layer_equals_the_usd_schema_classes_twin(tmp_path: Path, metadata: bool) -> None:
    from tests.datasets.scenes.usd_schema_twin import usd_proxy_text

    solids, surfaces, rooms, lights = _every_kind_of_prim()
    hints = ('{"openings":[]}', '{"spacing":0.5}') if metadata else (None, None)
    write_usd_proxy(tmp_path / "p.usda", solids, surfaces, hints[0], rooms, lights, hints[1])
    text = (tmp_path / "p.usda").read_text()
    assert text == usd_proxy_text(solids, surfaces, hints[0], rooms, lights, hints[1])
    for needle in ("SphereLight", "RectLight", "convexHull", 'purpose = "guide"', "paint__a0b0c0", "roughness = 0.4"):
        assert needle in text
    assert ("song_dressing" in text) == metadata
    # only the obstacles are read back as colliders, with their materials
    assert [(m.name, m.material) for m in read_usd_proxy(tmp_path / "p.usda")] == [
        ("wall_1", None),
        ("lamp_base", "metal_steel"),
        ("bare", None),
        ("painted", "paint:#a0b0c0"),
    ]


def test_a_generated_scene_proxy_equals_the_usd_schema_classes_twin(tmp_path: Path, monkeypatch) -> None:
    from song.datasets.scenes import usd
    from song.datasets.scenes.generate import generate_scene
    from tests.datasets.scenes.usd_schema_twin import usd_proxy_text

    calls = []
    real = usd.write_usd_proxy
    monkeypatch.setattr(usd, "write_usd_proxy", lambda path, *a, **k: calls.append((a, k)) or real(path, *a, **k))
    root = generate_scene("office_0000", "office", 0, tmp_path, splat=False)
    assert len(calls) == 1
    args, kwargs = calls[0]
    assert (root / "scene_flat.usda").read_text() == usd_proxy_text(*args, **kwargs)
