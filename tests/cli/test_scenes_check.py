"""``song scenes check DIR``: a table, one line per bad package, good ones still ok, exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from song.cli import app
from song.cli.common import console
from song.datasets.scenes.ply import GaussianCloud, write_compressed_ply
from song.datasets.scenes.usd import ProxyBox, write_usd_proxy
from tests.conftest import splat_file


def _run(folder: Path) -> tuple[int, str]:
    saved = console._width  # the shared rich console sizes itself once; a wide one keeps table rows whole
    console.width = 240
    try:
        result = CliRunner().invoke(app, ["scenes", "check", str(folder)])
    finally:
        console._width = saved
    return result.exit_code, result.output


def _with_optional_files(root: Path) -> Path:
    rng = np.random.default_rng(0)
    n = 300
    cloud = GaussianCloud(
        means=rng.uniform(0, 4, (n, 3)).astype(np.float32),
        quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        log_scales=np.full((n, 3), -3, np.float32),
        opacity_logits=np.zeros(n, np.float32),
        sh_dc=np.zeros((n, 3), np.float32),
    )
    write_compressed_ply(root / "3dgs_compressed.ply", cloud)
    write_usd_proxy(
        root / "scene_flat.usda", [ProxyBox("desk_1", np.array([[1, 0.5], [2, 0.5], [2, 1], [1, 1]]), 0, 0.75)]
    )
    return root


def test_mixed_folder_reports_each_bad_package_and_fails(make_scene, tmp_path: Path) -> None:
    good_a = _with_optional_files(make_scene("good_a"))
    make_scene("good_b")
    bad_version = make_scene("bad_version")
    data = json.loads((bad_version / "semantic_map.json").read_text())
    data["version"] = 3
    (bad_version / "semantic_map.json").write_text(json.dumps(data))
    (make_scene("no_occupancy") / "occupancy.png").unlink()
    truncated = make_scene("bad_ply")
    (truncated / "3dgs_compressed.ply").write_bytes(splat_file().read_bytes()[:100_000])
    (good_a.parent / "notes.txt").write_text("not a package")  # plain files are ignored

    code, out = _run(good_a.parent)
    assert code == 1
    lines = out.splitlines()
    assert any("scene packages in" in line for line in lines)  # the table title
    header = next(line for line in lines if "scene" in line and "status" in line and "splats" in line)
    assert "venue" in header and "obj" in header and "usd" in header
    row = {name: next(line for line in lines if line.startswith(f"{name} ")) for name in ("good_a", "good_b")}
    assert " ok " in row["good_a"] and "300" in row["good_a"] and "yes" in row["good_a"]  # splats, usd
    assert " ok " in row["good_b"]
    failed = [line for line in lines if line.startswith("FAILED ")]
    assert len(failed) == 3
    expected = {
        "bad_version": ("semantic_map.json: version", "unsupported version 3"),
        "no_occupancy": ("occupancy.png", "file is missing"),
        "bad_ply": ("3dgs_compressed.ply: vertex", "truncated"),
    }
    for name, (where, what) in expected.items():
        (line,) = [line for line in failed if line.startswith(f"FAILED {name}: ")]
        assert str(good_a.parent / name) in line and where in line and what in line, line
    assert out.rstrip().splitlines()[-1] == "2 ok, 3 failed"


def test_all_good_exits_zero(make_scene) -> None:
    root = _with_optional_files(make_scene("only"))
    make_scene("other")
    code, out = _run(root.parent)
    assert code == 0, out
    assert "FAILED" not in out and out.rstrip().endswith("2 ok, 0 failed")
    code, out = _run(root)  # a single package folder works too
    assert code == 0 and out.rstrip().endswith("1 ok, 0 failed")


def test_empty_or_missing_folder_fails(tmp_path: Path) -> None:
    code, out = _run(tmp_path)
    assert code == 1 and "no scene packages found" in out
    result = CliRunner().invoke(app, ["scenes", "check", str(tmp_path / "nope")])
    assert result.exit_code == 2 and "scenes folder is missing" in result.output


def test_shipped_samples_pass() -> None:
    samples = Path(__file__).resolve().parents[2] / "datasets" / "sample_scenes"
    code, out = _run(samples)
    assert code == 0, out
    assert "procthor_house_6" in out and "office_0000" in out
