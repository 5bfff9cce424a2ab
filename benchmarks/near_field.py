"""Near-field sharpness: how wide a sharp edge on a synthesised surface renders, by camera distance.

    .venv/bin/python benchmarks/near_field.py

A wall of surfels exactly as the scene synthesis lays them (``song.datasets.scenes.splat``: a jittered
grid at the default spacing, σ = WIDTH_FACTOR spacings across, THIN_FACTOR along the normal, opacity
0.993), half black and half white with the edge between two rows of samples (a picture frame, a
tile's grout, a door jamb), seen square-on by the robot camera (0.8 m high, 70°) from 0.3, 0.5, 1, 2
and 4 m at 320×240 and 960×540. Reported per case: the 10–90 % width of the edge in pixels (median
over the image rows that see it) and in millimetres on the wall, and a pixel's footprint on the wall.
An edge narrower than ~2 px reads as sharp; the issue's target is no blur closer than 0.5 m.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.datasets.scenes.splat import JITTER, OPACITY_LOGIT, SPACING_M, THIN_FACTOR, WIDTH_FACTOR  # noqa: E402
from song.render import GaussianSet, render, robot_camera  # noqa: E402
from song.render.gaussians import SH_C0  # noqa: E402

DISTANCES_M = (0.3, 0.5, 1.0, 2.0, 4.0)
SIZES = ((320, 240), (960, 540))
HFOV_DEG, HEIGHT_M = 70.0, 0.8


def wall(spacing: float = SPACING_M, seed: int = 0) -> GaussianSet:
    """Surfels on the plane x = 0 (facing −x), y ∈ [−3, 3], z ∈ [0, 2.5]; black for y < 0, white above."""
    rng = np.random.default_rng(seed)
    ys, zs = np.meshgrid(np.arange(-3.0, 3.0, spacing) + spacing / 2, np.arange(0.0, 2.5, spacing) + spacing / 2)
    n = ys.size
    y = ys.ravel() + JITTER * spacing * rng.uniform(-1, 1, n)
    z = zs.ravel() + JITTER * spacing * rng.uniform(-1, 1, n)
    means = np.column_stack([np.zeros(n), y, z])
    quat = np.tile([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0], (n, 1))  # local z (the thin axis) → x
    scales = np.tile([WIDTH_FACTOR * spacing, WIDTH_FACTOR * spacing, THIN_FACTOR * spacing], (n, 1))
    grey = np.where(ys.ravel() < 0, 0.05, 0.95)  # by the grid row, so the edge lies between two rows
    sh = np.repeat(((grey - 0.5) / SH_C0)[:, None], 3, axis=1)
    return GaussianSet.from_raw(means, quat, np.log(scales), np.full(n, OPACITY_LOGIT), sh)


def edge_width_px(image: np.ndarray) -> float:
    """Median over rows of the 10–90 % rise width of the dark-to-bright edge, in pixels (sub-pixel)."""
    widths = []
    for row in image:
        lo, hi = np.percentile(row, 2), np.percentile(row, 98)
        if hi - lo < 0.5:
            continue
        level = (row - lo) / (hi - lo)
        crossing = []
        for target in (0.1, 0.9):
            k = int(np.argmax(level >= target))
            if k == 0:
                break
            crossing.append(k - 1 + (target - level[k - 1]) / max(level[k] - level[k - 1], 1e-9))
        if len(crossing) == 2:
            widths.append(abs(crossing[1] - crossing[0]))
    return float(np.median(widths)) if widths else float("nan")


def main() -> None:
    surface = wall()
    cases = []
    for width, height in SIZES:
        for d in DISTANCES_M:
            # the camera at x = −d looking along +x: the edge (y = 0) runs vertically down the image
            camera = robot_camera(-d, 0.0, 0.0, HEIGHT_M, HFOV_DEG, width, height)
            out = render(surface, camera, "numba")
            grey = out.rgb_float.mean(axis=2)
            rows = grey[height // 4 : 3 * height // 4, ::-1]  # +y is to the left: flip so dark → bright
            px = edge_width_px(rows)
            footprint_mm = 1000.0 * d / camera.fx
            cases.append({"size": f"{width}x{height}", "distance_m": d, "edge_10_90_px": round(px, 2),
                          "edge_10_90_mm": round(px * footprint_mm, 1), "pixel_mm": round(footprint_mm, 2)})  # fmt: skip
    emit({"spacing_m": SPACING_M, "sigma_across_m": round(WIDTH_FACTOR * SPACING_M, 4), "cases": cases})


if __name__ == "__main__":
    main()
