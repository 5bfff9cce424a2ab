"""Robot-camera rendering speed: frames per second and where the time goes, per scene and resolution.

    .venv/bin/python benchmarks/render.py [--frames 8] [--backend numba]

Scenes (each with 5 avatars × 20 k Gaussians from the default pool standing 2–6 m in front of the
camera, as the runtime appends them):
- ``office_300k``: a procedural office synthesised at 5.2 cm spacing (~300 k Gaussians);
- ``office``: the same office at the default 3.5 cm spacing (~690 k);
- ``lobby_1m``: a procedural lobby at the default spacing (~1.02 M);
- ``biker``: the real 153 k-Gaussian SuperSplat capture (from ../shared; skipped when absent).
Resolutions 160×120, 320×240, 960×540; the camera is the paper's (0.8 m, 70°). Poses: for the
procedural scenes the view ``song viz view`` picks plus random free poses; for the biker, around it
at 3 m. Reported per scene and resolution: median FPS and the median milliseconds of each phase
(cull, project, sort, bin, composite). Targets (issue 16, CPU, 2 cores): ≥ 15 FPS at 320×240 with a
300 k-Gaussian scene + 5 avatars, ≥ 4 FPS at 960×540.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import BindingConfig  # noqa: E402
from song.datasets.avatars import load_avatar  # noqa: E402
from song.datasets.scenes import load_scene_package  # noqa: E402
from song.datasets.scenes.generate import generate_scene  # noqa: E402
from song.geometry.freespace import clearance_field  # noqa: E402
from song.pipeline.binding.pool import ensure_pool  # noqa: E402
from song.render import GaussianSet, render, robot_camera  # noqa: E402
from song.runtime.vision import scene_gaussians  # noqa: E402
from song.viz.view import pick_view  # noqa: E402

BIKER = ROOT.parent / "shared" / "sample_scenes" / "playcanvas_splat" / "biker.compressed.ply"
SIZES = [(160, 120), (320, 240), (960, 540)]
CAMERA_HEIGHT_M, HFOV_DEG = 0.8, 70.0
PHASES = ("cull", "project", "sort", "bin", "composite")


def _avatars() -> list[GaussianSet]:
    """Five pool avatars in their rest pose (20 k Gaussians each), activated, at the origin."""
    out = []
    for path in ensure_pool(BindingConfig())[:5]:
        g = load_avatar(path).gaussians
        out.append(GaussianSet.from_raw(g.means, g.quats, g.log_scales, g.opacity_logits, g.sh_dc, g.sh_rest))
    return out


def _place(avatars: list[GaussianSet], x: float, y: float, yaw: float) -> list[GaussianSet]:
    """The avatars standing 2–6 m ahead of a camera at (x, y, yaw), spread across its view."""
    placed = []
    for k, a in enumerate(avatars):
        dist, off = 2.0 + k, math.radians(-20 + 10 * k)
        px, py = x + dist * math.cos(yaw + off), y + dist * math.sin(yaw + off)
        means = a.means.copy()
        means[:, 0] += px
        means[:, 1] += py
        placed.append(GaussianSet(means, a.quats, a.scales, a.opacities, a.sh))
    return placed


def _procedural_poses(root: Path, count: int) -> list[tuple[float, float, float]]:
    poses = [pick_view(root, HFOV_DEG)]
    grid = load_scene_package(root).occupancy
    cells = np.argwhere(clearance_field(grid.free, grid.resolution) > 0.6)
    rng = np.random.default_rng(0)
    for r, c in cells[rng.choice(len(cells), count - 1, replace=False)]:
        x, y = grid.to_world(np.array([[r, c]]))[0]
        poses.append((float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
    return poses


def _measure(scene: GaussianSet, poses, avatars, frames: int, backend: str) -> dict:
    rows = {}
    for width, height in SIZES:
        times, phases = [], {p: [] for p in PHASES}
        for k in range(frames + 1):
            x, y, yaw = poses[k % len(poses)]
            camera = robot_camera(x, y, yaw, CAMERA_HEIGHT_M, HFOV_DEG, width, height)
            sets = [scene, *_place(avatars, x, y, yaw)]
            profile: dict[str, float] = {}
            start = time.perf_counter()
            render(sets, camera, backend, profile=profile)
            if k:  # the first frame warms caches
                times.append(time.perf_counter() - start)
                for p in PHASES:
                    phases[p].append(profile.get(p, 0.0))
        rows[f"{width}x{height}"] = {
            "fps": round(1.0 / float(np.median(times)), 2),
            "ms": {p: round(1000 * float(np.median(v)), 1) for p, v in phases.items()},
        }
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--backend", default="numba")
    args = parser.parse_args()
    avatars = _avatars()
    record: dict = {
        "backend": args.backend,
        "cpu_count": os.cpu_count(),
        "load_1min": round(os.getloadavg()[0], 2),
        "avatar_gaussians": [len(a) for a in avatars],
    }
    tmp = Path(tempfile.mkdtemp(prefix="song-render-"))
    scenes = {
        "office_300k": generate_scene("office_0000", "office", 7, tmp / "s300", True, 0.052),
        "office": generate_scene("office_0000", "office", 7, tmp / "s", True),
        "lobby_1m": generate_scene("lobby_0002", "lobby", 7, tmp / "s", True),
    }
    results = {}
    for name, root in scenes.items():
        scene = scene_gaussians(root / "3dgs_compressed.ply")
        results[name] = {
            "gaussians": len(scene),
            **_measure(scene, _procedural_poses(root, 4), avatars, args.frames, args.backend),
        }
    if BIKER.is_file():
        scene = scene_gaussians(BIKER)
        centre = np.median(scene.means, axis=0)
        poses = []
        for k in range(4):  # around the capture at 3 m, looking at its centre (camera 0.8 m above its floor)
            a = 2 * math.pi * k / 4
            poses.append((float(centre[0] - 3 * math.cos(a)), float(centre[1] - 3 * math.sin(a)), a))
        results["biker"] = {"gaussians": len(scene), **_measure(scene, poses, avatars, args.frames, args.backend)}
    else:
        results["biker"] = f"skipped: {BIKER} is absent (third-party splats live in ../shared)"
    record["scenes"] = results
    record["targets"] = {"fps_320x240_300k": 15, "fps_960x540": 4}
    emit(record)


if __name__ == "__main__":
    main()
