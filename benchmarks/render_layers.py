"""Where compositing spends its work: contributions per pixel and how far transmittance falls, per view.

    .venv/bin/python benchmarks/render_layers.py --bench runs/demo-bench [--episodes 6] [--resolution 320x240]

For the robot camera at the start of the first ``--episodes`` test episodes of a release (scene and
posed avatars, as the runtime renders them), it runs the numba compositing kernel with counters
inserted into a copy of its source at run time (so the counted kernel is the shipped one, line for
line): Gaussians visited per tile, pixels tested, σ tests passed, contributions (α ≥ 1/255 before
the pixel stops), and the final transmittance of every pixel. Also, from a numpy model of one
surface (a jittered grid of surfels with SONG's σ = 0.6 spacings and opacity 0.993), the share of
pixels whose transmittance falls to the stopping threshold 1e-4 within that one surface.

It also sizes the proposed fix (culling what lies behind the first surface): with an oracle first
surface, the rendered depth of the view's covered pixels (alpha > 0.5) maximised per tile, Gaussians
farther than that plus ``CULL_MARGIN_M`` in every tile they touch are dropped before binning; the
shipped compositing kernel is then timed on both lists (median of 5 calls) and the images compared.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import inspect
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.datasets.bench import open_benchmark  # noqa: E402
from song.render import _render_kernel as kernel  # noqa: E402
from song.render.render import tile_lists  # noqa: E402
from song.runtime.robot import Pose  # noqa: E402
from song.runtime.vision import SceneView  # noqa: E402

COUNTERS = {  # (line of the kernel, counter index) inserted after that line
    "            a = attr[ids[e]]\n": 0,
    "            for i in range(r0, r1):\n": 1,
    "                for j in range(j0, j1):\n": 2,
    "                    alpha = min(ALPHA_MAX, o * exp_neg(sigma))\n": 3,
    "                    w = alpha * tp\n": 4,
}
CULL_MARGIN_M = 0.3  # kept behind the first surface (furniture against a wall, a wall's thickness)
NAMES = ("gaussians_visited", "rows_visited", "pixels_tested", "sigma_passed", "contributions")


def counted_kernel():
    """The compositing kernel with ``counts[t, k] += 1`` after each line of :data:`COUNTERS`."""
    source = inspect.getsource(sys.modules[kernel.__name__])
    start = source.index("@numba.njit(cache=True, parallel=True, fastmath=True)\ndef composite_kernel")
    body = source[start:].replace("@numba.njit(cache=True, parallel=True, fastmath=True)", "@numba.njit(parallel=True)")
    body = body.replace(
        "background, out_rgb, out_depth, out_alpha):", "background, out_rgb, out_depth, out_alpha, counts):", 1
    )
    for line, k in COUNTERS.items():
        indent = " " * (len(line) - len(line.lstrip()) + (4 if line.rstrip().endswith(":") else 0))
        assert line in body, line
        body = body.replace(line, f"{line}{indent}counts[t, {k}] += 1\n", 1)
    path = Path(tempfile.mkdtemp()) / "counted_kernel.py"
    path.write_text(source[:start] + body)
    spec = importlib.util.spec_from_file_location("counted_kernel", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.composite_kernel


def one_surface(opacity: float = 1 / (1 + np.exp(-5.0)), sigma: float = 0.6, trials: int = 400) -> dict:
    """Transmittance through one surface of jittered surfels (spacing 1), as SONG synthesises them."""
    rng = np.random.default_rng(0)
    g = np.arange(-5, 6)
    lattice = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2).astype(float)
    finals = []
    for _ in range(trials):
        centres = lattice + rng.uniform(-0.25, 0.25, lattice.shape)
        pixels = rng.uniform(0, 1, (50, 2))
        d2 = ((pixels[:, None] - centres[None]) ** 2).sum(-1)
        alpha = np.minimum(kernel.ALPHA_MAX, opacity * np.exp(-d2 / (2 * sigma**2)))
        finals.append(np.prod(np.where(alpha >= kernel.ALPHA_MIN, 1 - alpha, 1.0), axis=1))
    t = np.concatenate(finals)
    return {"median_T": float(np.median(t)), "p99_T": float(np.percentile(t, 99)),
            "share_reaching_1e-4": float((t <= kernel.T_MIN).mean())}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", required=True)
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--resolution", default="320x240")
    args = parser.parse_args()
    width, height = (int(v) for v in args.resolution.split("x"))
    composite = counted_kernel()
    bench = open_benchmark(args.bench)
    view = SceneView("numba")
    rows = []
    for summary in list(bench.episodes(split="test"))[: args.episodes]:
        episode = dataclasses.replace(bench.episode(summary.episode_id), params=bench.params)
        view.reset(episode)
        pose = Pose(float(episode.start_xy[0]), float(episode.start_xy[1]), float(episode.start_yaw))
        _, sets, camera = view.request(pose, 1.0, width, height)
        lists = tile_lists([(sets, camera)])
        offsets, ids, attr, tiles_x, tiles_y = lists.offsets, lists.ids, lists.attr, lists.tiles_x, lists.tiles_y
        counts = np.zeros((tiles_x * tiles_y, len(NAMES)), np.int64)
        rgb = np.empty((1, height, width, 3), np.float32)
        depth = np.empty((1, height, width), np.float32)
        alpha = np.empty((1, height, width), np.float32)
        composite(offsets, ids, attr, width, height, tiles_x, tiles_y, np.zeros(3), rgb, depth, alpha, counts)
        per_pixel = counts.sum(axis=0) / (width * height)
        t = 1.0 - alpha[0].astype(np.float64)
        rows.append({"episode": summary.episode_id, **{n: round(float(v), 2) for n, v in zip(NAMES, per_pixel, strict=True)},
                     "pixels_stopped_at_1e-4": round(float((t <= kernel.T_MIN * 1.0001).mean()), 4),
                     "median_final_T": float(np.median(t)), "tile_list_entries_per_pixel": round(len(ids) / (width * height), 2),
                     "oracle_cull": oracle_cull(attr, lists.order, lists.rect, depth[0], alpha[0], rgb[0], (width, height, tiles_x, tiles_y))})  # fmt: skip
    emit({"resolution": args.resolution, "views": rows, "one_surface_model": one_surface()})


def _time_composite(offsets, ids, attr, size) -> tuple[float, np.ndarray, np.ndarray]:
    import time

    width, height, tiles_x, tiles_y = size
    rgb = np.empty((1, height, width, 3), np.float32)
    depth = np.empty((1, height, width), np.float32)
    alpha = np.empty((1, height, width), np.float32)
    times = []
    for _ in range(5):
        start = time.perf_counter()
        kernel.composite_kernel(offsets, ids, attr, width, height, tiles_x, tiles_y, np.zeros(3), rgb, depth, alpha)
        times.append(time.perf_counter() - start)
    return float(np.median(times)), rgb[0], depth[0]


def oracle_cull(attr, order, rect, depth, alpha, rgb, size) -> dict:
    """Composite time and image change when Gaussians behind the (oracle) first surface are dropped."""
    width, height, tiles_x, tiles_y = size
    tile_max = np.full((tiles_y, tiles_x), np.inf)
    for ty in range(tiles_y):
        for tx in range(tiles_x):
            block = (slice(ty * kernel.TILE, (ty + 1) * kernel.TILE), slice(tx * kernel.TILE, (tx + 1) * kernel.TILE))
            if (alpha[block] > 0.5).all():
                tile_max[ty, tx] = float(depth[block].max())
    keep = np.ones(len(order), bool)
    for q, g in enumerate(order):
        x0, x1, y0, y1 = rect[g]
        keep[q] = attr[g, kernel.Z] <= tile_max[y0:y1, x0:x1].max() + CULL_MARGIN_M
    full_offsets, full_ids = kernel.bin_kernel(order, rect, tiles_x, tiles_y, 8)
    kept_offsets, kept_ids = kernel.bin_kernel(order[keep], rect, tiles_x, tiles_y, 8)
    full_s, full_rgb, full_depth = _time_composite(full_offsets, full_ids, attr, size)
    kept_s, kept_rgb, kept_depth = _time_composite(kept_offsets, kept_ids, attr, size)
    covered = alpha > 0.5
    return {"gaussians_kept": round(float(keep.mean()), 3), "composite_ms_full": round(1e3 * full_s, 2),
            "composite_ms_culled": round(1e3 * kept_s, 2),
            "rgb_mean_abs_change_255": round(float(np.abs(kept_rgb - full_rgb).mean() * 255), 3),
            "rgb_max_abs_change_255": round(float(np.abs(kept_rgb - full_rgb).max() * 255), 2),
            "depth_median_abs_change_m": float(np.median(np.abs(kept_depth - full_depth)[covered]))}  # fmt: skip


if __name__ == "__main__":
    main()
