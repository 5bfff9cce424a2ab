"""Every ``song viz`` command writes a non-blank picture of the right size with the map drawn."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from song.cli import app
from tests.conftest import SAMPLES

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"


def _check(path: Path, min_size: int = 200) -> np.ndarray:
    image = cv2.imread(str(path))
    assert image is not None and min(image.shape[:2]) >= min_size
    assert image.std() > 10  # not blank
    return image


def test_viz_scene_and_crowd(sample_run: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = tmp_path / "scene.png"
    assert runner.invoke(app, ["viz", "scene", str(SAMPLES / "procthor_house_6"), "--out", str(out)]).exit_code == 0
    image = _check(out)
    floor = np.all(np.abs(image.astype(int) - [238, 243, 245]) < 12, axis=-1)  # floor colour (BGR)
    assert floor.mean() > 0.02
    result = runner.invoke(
        app, ["viz", "crowd", str(sample_run), "--scene", "procthor_house_6", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    _check(tmp_path / "procthor_house_6_crowd.png")
    assert (tmp_path / "procthor_house_6_crowd.mp4").stat().st_size > 10_000


def test_viz_bench_and_episode(tmp_path: Path) -> None:
    runner = CliRunner()
    assert (
        runner.invoke(
            app, ["eval", "--bench", str(GOLDEN), "--policy", "astar", "--out", str(tmp_path / "ev")]
        ).exit_code
        == 0
    )
    result = runner.invoke(
        app, ["viz", "bench", str(GOLDEN), "--out", str(tmp_path), "--results", str(tmp_path / "ev/astar.json")]
    )
    assert result.exit_code == 0, result.output
    for name in ("encounters_vs_length", "factors", "modes", "results"):
        _check(tmp_path / f"{name}.png")
    result = runner.invoke(
        app,
        [
            "viz",
            "episode",
            str(GOLDEN),
            "--episode",
            "scene_0-001",
            "--results",
            str(tmp_path / "ev/astar.parquet"),
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    image = _check(tmp_path / "scene_0-001.png")
    assert (np.abs(image.astype(int) - [200, 40, 40]).sum(axis=-1) < 60).any()  # the dashed A* path (BGR)
