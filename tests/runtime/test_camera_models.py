"""The d435i camera model: depth error growing with z², range limits, occlusion holes, determinism."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from song.cli import app
from song.config import CameraConfig
from song.datasets.bench.types import RuntimeParams
from song.render import RenderOutput
from song.render.camera import focal_from_hfov
from song.runtime.camera_models import D435iCamera, depth_sigma_m, occluded
from song.runtime.robot import Pose
from song.runtime.vision import CameraContext

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"
PARAMS = RuntimeParams(camera=CameraConfig())


def _frame(depth: np.ndarray) -> RenderOutput:
    h, w = depth.shape
    rgb = np.full((h, w, 3), 0.5, np.float32)
    return RenderOutput((rgb * 255).astype(np.uint8), depth.astype(np.float32), (depth > 0).astype(np.float32), rgb)


def _context(step: int = 3, turn: float = 0.0) -> CameraContext:
    return CameraContext(seed=7, t=0.1 * step, pose=Pose(0.0, 0.0, 0.0), command=(0.3, turn))


@pytest.mark.parametrize("z", [1.0, 2.0, 4.0])
def test_depth_error_grows_with_the_square_of_the_distance_as_stated(z: float) -> None:
    out = D435iCamera(PARAMS).apply(_frame(np.full((240, 320), z)), _context())
    error = out.depth[out.depth > 0] - z
    assert depth_sigma_m(2.0) == pytest.approx(0.04)  # the datasheet's 2 % at 2 m
    assert np.sqrt(np.mean(error**2)) == pytest.approx(depth_sigma_m(z), rel=0.05)
    assert abs(error.mean()) < 0.1 * depth_sigma_m(z)  # unbiased


def test_the_same_episode_and_step_give_the_same_image_and_another_step_another() -> None:
    frame = _frame(np.full((60, 80), 2.0))
    model = D435iCamera(PARAMS)
    a, b, c = model.apply(frame, _context(3)), model.apply(frame, _context(3)), model.apply(frame, _context(4))
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    assert not np.array_equal(a.depth, c.depth)


def test_depth_only_where_the_ideal_render_had_it_and_within_range() -> None:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.05, 14.0, (120, 160))
    depth[rng.random(depth.shape) < 0.2] = 0.0
    out = D435iCamera(PARAMS).apply(_frame(depth), _context())
    assert not ((depth == 0) & (out.depth > 0)).any()
    assert not (out.depth[(depth < 0.28) | (depth > 10.0)]).any()


def test_a_foreground_edge_casts_a_hole_as_wide_as_the_disparity_step_on_its_left() -> None:
    depth = np.full((20, 200), 4.0)
    depth[:, 100:140] = 1.0  # a post 1 m away in front of a wall at 4 m
    focal = focal_from_hfov(200, PARAMS.camera.hfov_deg)
    holes = occluded(depth, focal)
    width = focal * 0.05 * (1 / 1.0 - 1 / 4.0)  # disparity step, px
    row = holes[10]
    assert row[100 - int(width) + 1 : 100].all() and not row[: 100 - int(width) - 1].any()
    assert not row[100:].any()  # the right edge exposes nothing the right imager misses


def test_turning_blurs_the_colour_image_along_the_rows() -> None:
    image = np.full((40, 640), 0.35, np.float32)
    image[:, ::16] = 0.6  # vertical stripes; at 640 px a 0.8 rad/s turn moves the image 3.7 px in 10 ms
    frame = _frame(np.full((40, 640), 2.0))
    frame = RenderOutput(
        (np.repeat(image[..., None], 3, 2) * 255).astype(np.uint8), frame.depth, frame.alpha, frame.rgb_float
    )
    still, turning = (D435iCamera(PARAMS).apply(frame, _context(turn=w)) for w in (0.0, 0.8))
    columns = [x.rgb[..., 1].astype(float).mean(axis=0) for x in (still, turning)]  # the noise averages out
    sharpness = [np.abs(np.diff(c)).mean() / c.mean() for c in columns]
    assert sharpness[1] < 0.5 * sharpness[0]


def test_eval_records_the_camera_model_and_marks_another_than_the_release_s(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    args = ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--sensors", "depth", "--resolution", "32x24"]
    result = CliRunner().invoke(app, [*args, "--camera-model", "d435i", "--out", str(out), "--render-backend", "numba"])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "straight.json").read_text())
    assert summary["overrides"] == {"camera.model": ["ideal", "d435i"]} and summary["official"] is False
    assert {s["name"]: s for s in summary["sensors"]}["depth"]["camera_model"] == "d435i"
