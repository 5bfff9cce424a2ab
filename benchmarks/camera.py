"""The d435i camera model against its stated error curve, its holes at silhouettes and its cost.

    .venv/bin/python benchmarks/camera.py [--bench runs/demo-bench] [--frames 20]

- **Depth error on flat walls**: a dense surfel wall rendered by the real renderer 1, 2 and 4 m in front
  of the robot camera (320×240); the RMS of d435i depth minus the ideal depth over the central half of
  the image, against the model's curve σ(z) = z² σ_d / (f B) (2 % at 2 m). Target: within ±20 %.
- **Holes at silhouettes**: on robot-camera frames of the release (start poses of its first episodes),
  the share of pixels next to a depth step of more than 0.3 m that read 0 in d435i depth, and the share
  of all valid pixels that do.
- **Cost**: the model's time per 320×240 frame against the render's, interleaved. Target ≤ 5 %.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.config import CameraConfig  # noqa: E402
from song.datasets.bench import open_benchmark  # noqa: E402
from song.datasets.bench.types import RuntimeParams  # noqa: E402
from song.render import GaussianSet, render, robot_camera  # noqa: E402
from song.runtime.camera_models import D435iCamera, depth_sigma_m  # noqa: E402
from song.runtime.robot import Pose  # noqa: E402
from song.runtime.vision import CameraContext, SceneView  # noqa: E402

W, H = 320, 240


def _wall(distance: float, spacing: float = 0.02) -> GaussianSet:
    """A surfel wall facing the camera: the plane x = distance, 10 m wide and 3 m tall."""
    y, z = np.meshgrid(np.arange(-5.0, 5.0, spacing), np.arange(0.0, 3.0, spacing))
    n = y.size
    means = np.column_stack([np.full(n, distance), y.ravel(), z.ravel()])
    half = np.sqrt(0.5)
    quats = np.tile([half, 0.0, half, 0.0], (n, 1))  # local z → world x: the surfel's normal faces the camera
    scales = np.tile([0.6 * spacing, 0.6 * spacing, 0.06 * spacing], (n, 1))
    return GaussianSet(means, quats, scales, np.full(n, 0.99), np.zeros((n, 1, 3)))


def flat_walls(model: D435iCamera) -> dict:
    out = {}
    camera = robot_camera(0.0, 0.0, 0.0, 0.8, 70.0, W, H)
    for z in (1.0, 2.0, 4.0):
        ideal = render(_wall(z), camera, "numba")
        errors = []
        for step in range(10):
            real = model.apply(ideal, CameraContext(1, 0.1 * step, Pose(0.0, 0.0, 0.0)))
            centre = (slice(H // 4, 3 * H // 4), slice(W // 4, 3 * W // 4))
            valid = real.depth[centre] > 0
            errors.append((real.depth[centre] - ideal.depth[centre])[valid])
        rms = float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))
        stated = float(depth_sigma_m(z))
        out[f"{z:g}m"] = {"rms_m": round(rms, 5), "model_m": round(stated, 5), "ratio": round(rms / stated, 3)}
    return out


def release_frames(bench_path: str, frames: int, model: D435iCamera) -> dict:
    bench = open_benchmark(bench_path)
    view = SceneView("numba", "ideal")
    edge_holes, edges, all_holes, valid, render_s, model_s = 0, 0, 0, 0, [], []
    for episode in list(bench.episodes())[:frames]:
        view.reset(episode)
        pose = Pose(float(episode.start_xy[0]), float(episode.start_xy[1]), float(episode.start_yaw))
        start = time.perf_counter()
        ideal = view.render(pose, float(episode.t0) + 0.05, W, H)
        render_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        real = model.apply(ideal, CameraContext(int(episode.seed), float(episode.t0), pose, (0.3, 0.3)))
        model_s.append(time.perf_counter() - start)
        d = ideal.depth
        step = np.zeros(d.shape, bool)
        step[:, 1:] |= np.abs(np.diff(d, axis=1)) > 0.3
        step[:, :-1] |= np.abs(np.diff(d, axis=1)) > 0.3
        near_edge = step & (d > 0)
        holes = (d > 0) & (real.depth == 0)
        edge_holes += int((holes & near_edge).sum())
        edges += int(near_edge.sum())
        all_holes += int(holes.sum())
        valid += int((d > 0).sum())
    return {
        "frames": len(render_s),
        "hole_share_at_silhouettes": round(edge_holes / max(edges, 1), 3),
        "hole_share_of_valid_pixels": round(all_holes / max(valid, 1), 4),
        "render_ms_median": round(1000 * float(np.median(render_s)), 1),
        "model_ms_median": round(1000 * float(np.median(model_s)), 2),
        "model_share_of_frame": round(float(np.median(model_s)) / float(np.median(render_s)), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", default="runs/demo-bench")
    parser.add_argument("--frames", type=int, default=20)
    args = parser.parse_args()
    model = D435iCamera(RuntimeParams(camera=CameraConfig()))
    record = {"flat_walls": flat_walls(model)}
    if Path(args.bench).exists():
        record["release"] = release_frames(args.bench, args.frames, model)
    record["targets"] = {"flat_wall_ratio": [0.8, 1.2], "model_share_of_frame": 0.05}
    emit(record)


if __name__ == "__main__":
    main()
