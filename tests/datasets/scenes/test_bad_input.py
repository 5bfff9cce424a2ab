"""A catalogue of malformed packages: each gets its own one-line error naming the file and the field."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from plyfile import PlyData, PlyElement
from typer.testing import CliRunner

from song.cli import app
from song.datasets.scenes import load_scene_package
from song.errors import SceneError
from tests.conftest import splat_file


@pytest.fixture(autouse=True)
def _confined(nothing_written_outside) -> None:
    """Every case here must leave everything outside its own tmp_path as it was."""


def _edit_map(fn: Callable[[dict], None]) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        data = json.loads((root / "semantic_map.json").read_text())
        fn(data)
        (root / "semantic_map.json").write_text(json.dumps(data))

    return apply


def _set(path: str, value) -> Callable[[Path], None]:
    def fn(data: dict) -> None:
        keys = path.split(".")
        target = data
        for key in keys[:-1]:
            target = target[int(key)] if key.isdigit() else target[key]
        last = keys[-1]
        target[int(last) if last.isdigit() else last] = value

    return _edit_map(fn)


def _image(fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        cells = cv2.imread(str(root / "occupancy.png"), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(root / "occupancy.png"), fn(cells))

    return apply


def _write(name: str, data: bytes) -> Callable[[Path], None]:
    return lambda root: (root / name).write_bytes(data)


PLY = "3dgs_compressed.ply"
USD = "scene_flat.usda"


def _ply(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    """A package PLY made from a real-sized compressed file with its arrays edited."""

    def apply(root: Path) -> None:
        ply = PlyData.read(str(splat_file()))
        arrays = {e.name: np.array(e.data) for e in ply.elements}
        edit(arrays)
        PlyData([PlyElement.describe(a, k) for k, a in arrays.items()], text=False).write(str(root / PLY))

    return apply


def _retype_packed(arrays: dict) -> None:
    v = arrays["vertex"]
    arrays["vertex"] = v.astype([(k, "<f4" if k == "packed_color" else "<u4") for k in v.dtype.names])


def _drop(path: str) -> Callable[[Path], None]:
    return _edit_map(lambda data: data.pop(path))


USDA_Y_UP = b'#usda 1.0\n(\n    metersPerUnit = 1\n    upAxis = "Y"\n)\n'
EMPTY_PLY = (
    b"ply\nformat binary_little_endian 1.0\nelement vertex 0\n"
    + b"".join(
        b"property float %s\n" % k.encode()
        for k in ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2"]
        + ["rot_0", "rot_1", "rot_2", "rot_3"]
    )
    + b"end_header\n"
)


CATALOGUE: list[tuple[str, Callable[[Path], None], str, str]] = [
    ("missing map", lambda r: (r / "semantic_map.json").unlink(), "semantic_map.json", "missing"),
    ("missing occupancy", lambda r: (r / "occupancy.png").unlink(), "occupancy.png", "missing"),
    ("wrong format", _set("format", "other.map"), "semantic_map.json: format", "expected"),
    ("wrong version", _set("version", 2), "semantic_map.json: version", "unsupported version"),
    ("nan coordinate", _set("objects.0.footprint.0.0", float("nan")), "objects[0].footprint", "finite"),
    ("infinite bound", _set("bounds.2", float("inf")), "bounds", "finite"),
    ("too few vertices", _set("objects.1.footprint", [[6, 3], [7, 3]]), "objects[1].footprint", "at least 3"),
    (
        "self-intersecting",
        _set("regions.0.polygon", [[0, 0], [4, 4], [4, 0], [0, 4]]),
        "regions[0].polygon",
        "self-intersecting",
    ),
    ("degenerate polygon", _set("regions.1.polygon", [[4, 0], [5, 0], [6, 0]]), "regions[1].polygon", "degenerate"),
    ("object outside", _set("objects.2.footprint", [[20, 20], [21, 20], [21, 21]]), "objects[2].footprint", "outside"),
    ("duplicate id", _set("objects.1.id", "desk_1"), "objects[1].id", "duplicate"),
    ("region/object id clash", _set("objects.0.id", "room_a"), "objects[0].id", "duplicate"),
    ("unknown region", _set("objects.0.region", "attic"), "objects[0].region", "unknown region"),
    ("z_max below z_min", _set("objects.0.z_min", 2.0), "objects[0].z_max", "below"),
    ("resolution out of range", _set("occupancy.resolution", 0.9), "occupancy.resolution", "[0.01, 0.5]"),
    ("image size mismatch", _set("bounds", [0, 0, 9, 4]), "occupancy.png: size", "bounds/resolution"),
    ("origin off bounds", _set("occupancy.origin", [1.0, 0.0]), "occupancy.origin", "lower-left"),
    ("no free space", _image(lambda c: np.zeros_like(c)), "occupancy.png: free", "largest free area"),
    (
        "odd pixel values",
        _image(lambda c: np.where(c == 255, 200, c).astype(np.uint8)),
        "occupancy.png: pixels",
        "unexpected values",
    ),
    ("colour image", _image(lambda c: np.dstack([c, c, c])), "occupancy.png", "single-channel"),
    ("not a png", _write("occupancy.png", b"\x89PNG\r\n\x1a\n broken"), "occupancy.png", "readable PNG"),
    ("non-utf8 json", _write("semantic_map.json", b'{"scene_id": "\xff\xfe"}'), "semantic_map.json", "UTF-8"),
    ("invalid json", _write("semantic_map.json", b'{"scene_id": '), "semantic_map.json", "not valid JSON"),
    ("json array", _write("semantic_map.json", b"[1, 2]"), "semantic_map.json", "JSON object"),
    ("scene id with slash", _set("scene_id", "a/b"), "semantic_map.json: scene_id", "path separators"),
    ("scene id with dots", _set("scene_id", "..x"), "semantic_map.json: scene_id", "path separators"),
    ("scene id not folder", _set("scene_id", "other"), "semantic_map.json: scene_id", "folder name"),
    ("unknown field", _set("colour", "red"), "semantic_map.json: colour", "Extra inputs"),
    ("path in occupancy", _set("occupancy.path", "../x.png"), "occupancy.path", "file name"),
    ("missing bounds", _drop("bounds"), "semantic_map.json: bounds", "Field required"),
    ("version not a number", _set("version", "one"), "semantic_map.json: version", "valid integer"),
    ("inverted bounds", _set("bounds", [8, 0, 0, 4]), "semantic_map.json: bounds", "x_max > x_min"),
    ("nan height", _set("objects.0.z_max", float("nan")), "objects[0].z_max", "finite"),
    ("feet", _set("frame.units", "ft"), "semantic_map.json: frame.units", "'m'"),
    (
        "self-intersecting footprint",
        _set("objects.0.footprint", [[1, 0.5], [2, 1], [2, 0.5], [1, 1]]),
        "objects[0].footprint",
        "self-intersecting",
    ),
    ("16-bit occupancy", _image(lambda c: c.astype(np.uint16) * 257), "occupancy.png", "8-bit"),
    (
        "truncated ply",
        lambda r: (r / PLY).write_bytes(splat_file().read_bytes()[:700_000]),
        f"{PLY}: vertex",
        "truncated",
    ),
    ("garbage ply", _write(PLY, b"PK\x03\x04 a zip, not a ply"), f"{PLY}: header", "not a readable PLY"),
    ("ply without splats", _write(PLY, EMPTY_PLY), f"{PLY}: vertex", "no splats"),
    ("ply chunk count", _ply(lambda a: a.update(chunk=a["chunk"][:-2])), f"{PLY}: chunk", "cannot hold"),
    ("ply packed as float", _ply(_retype_packed), f"{PLY}: vertex.packed_color", "float32, expected uint32"),
    ("usd binary", _write(USD, b"PXR-USDC\x00\x00"), f"{USD}: header", "not a USD text layer"),
    ("usd y up", _write(USD, USDA_Y_UP), f"{USD}: upAxis", 'upAxis = "Z"'),
]


@pytest.mark.parametrize(("name", "damage", "where", "what"), CATALOGUE, ids=[c[0] for c in CATALOGUE])
def test_each_problem_has_its_own_message(make_scene, name: str, damage, where: str, what: str) -> None:
    root = make_scene()
    damage(root)
    with pytest.raises(SceneError) as info:
        load_scene_package(root)
    message = str(info.value)
    assert "\n" not in message
    assert where in message and what in message, message
    assert str(root) in message


def test_messages_are_distinct(make_scene, tmp_path: Path) -> None:
    seen = set()
    for index, (_, damage, _, _) in enumerate(CATALOGUE):
        root = make_scene(f"s{index}", root=tmp_path / f"c{index}")
        damage(root)
        with pytest.raises(SceneError) as info:
            load_scene_package(root)
        seen.add(str(info.value).replace(str(root), ""))
    assert len(seen) >= 20


def test_check_command_carries_on(make_scene, tmp_path: Path) -> None:
    good = make_scene("good")
    bad = make_scene("bad")
    _set("version", 3)(bad)
    broken = make_scene("broken")
    (broken / "occupancy.png").unlink()
    result = CliRunner().invoke(app, ["scenes", "check", str(good.parent)])
    assert result.exit_code == 1
    text = " ".join(result.output.split())
    assert "good" in text and "2 failed" in text and "1 ok" in text
    ok = CliRunner().invoke(app, ["scenes", "check", str(good)])
    assert ok.exit_code == 0, ok.output
