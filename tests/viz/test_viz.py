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
        app, ["viz", "crowd", "--run", str(sample_run), "--scene", "procthor_house_6", "--out", str(tmp_path)]
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
    result = runner.invoke(  # --results: a policy's output named by its stem
        app, ["viz", "bench", "--bench", str(GOLDEN), "--out", str(tmp_path), "--results", str(tmp_path / "ev/astar")]
    )
    assert result.exit_code == 0, result.output
    for name in ("encounters_vs_length", "factors", "modes", "results"):
        _check(tmp_path / f"{name}.png")
    result = runner.invoke(
        app,
        [
            "viz",
            "episode",
            str(GOLDEN),  # the benchmark as a bare first argument, as before --bench
            "--episode",
            "scene_0-001",
            "--results",
            str(tmp_path / "ev/astar.json"),  # the summary's name: the per-episode table beside it is read
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    image = _check(tmp_path / "scene_0-001.png")
    assert (np.abs(image.astype(int) - [200, 40, 40]).sum(axis=-1) < 60).any()  # the dashed A* path (BGR)
    for args, message in (
        (["viz", "episode", str(GOLDEN), "--bench", str(tmp_path), "--episode", "x"], "two benchmarks"),
        (["viz", "episode", "--episode", "x"], "missing --bench"),
        (["viz", "bench", "--bench", str(GOLDEN), "--results", str(tmp_path / "ev/nope")], "--results takes"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 2 and message in result.output, result.output


def test_viz_pov_writes_an_h264_video_and_a_strip(tmp_path: Path) -> None:
    import av
    import pyarrow.parquet as pq

    result = CliRunner().invoke(
        app,
        ["viz", "pov", "--bench", str(GOLDEN), "--episode", "scene_0-001", "--policy", "straight", "--resolution", "96x72",
         "--out", str(tmp_path)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    with av.open(str(tmp_path / "scene_0-001_straight_pov.mp4")) as video:
        stream = video.streams.video[0]
        assert stream.codec_context.name == "h264" and stream.codec_context.pix_fmt == "yuv420p"
        frames = [f.to_ndarray(format="rgb24") for f in video.decode(video=0)]
    ev = CliRunner().invoke(
        app, ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--out", str(tmp_path / "ev")]
    )
    assert ev.exit_code == 0, ev.output
    table = pq.read_table(tmp_path / "ev" / "straight.parquet").to_pylist()
    steps = next(r["steps"] for r in table if r["episode_id"] == "scene_0-001")
    assert len(frames) == steps  # one frame per control step, the same run as song eval's
    _check(tmp_path / "scene_0-001_straight_pov.png", min_size=100)


def test_viz_view_renders_a_room(tmp_path: Path) -> None:
    from song.datasets.scenes.generate import generate_scene
    from song.datasets.scenes.splat import dress_package

    root = generate_scene("office_0000", "office", 1, tmp_path / "scenes", False, 0.1)
    dress_package(root, spacing=0.1, light=False)  # evenly lit: a dark pixel can only be the void
    out = tmp_path / "view.png"
    result = CliRunner().invoke(app, ["viz", "view", str(root), "--out", str(out), "--resolution", "160x90"])
    assert result.exit_code == 0, result.output
    image = _check(out, min_size=90)
    assert (image.max(axis=-1) > 40).mean() > 0.98  # a closed room: surfaces everywhere, no void
