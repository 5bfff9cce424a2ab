"""GPU paths on a real CUDA device, one JSON object: gsplat parity and throughput, GPU LBS, the closed loop.

    python benchmarks/gpu.py --bench RELEASE --scene NAME=PLY [--scene ...] --out DIR

Needs torch with CUDA and ``gsplat`` (``pip install 'song[gpu]'``; gsplat compiles its CUDA code on first
use, timed here as ``gsplat_build_s``). Sections, each recorded even when another fails:

- **parity**: the release's first episodes rendered at 960×540 with their posed avatars, plus every
  ``--scene`` PLY with the release's avatars placed 2–6 m ahead of the camera, through ``numba`` and
  ``gsplat``: RGB PSNR (uint8), depth |Δ| p99 over pixels with alpha > 0.5 in both, alpha |Δ| max.
  Targets: ≥ 40 dB, ≤ 1 cm, ≤ 1e-3. One picture per scene (gsplat | numba | 10·|Δ|) goes to ``--out``.
- **throughput**: the largest ``--scene`` + 5 avatars at 960×540, end to end through
  :func:`song.render.render` (avatars uploaded each frame, images read back), the rasterizer alone
  on resident tensors, and 16 cameras in one :func:`song.render.render_batch` call; numba on this
  machine's CPU as the peer.
- **lbs**: Gaussian-frames per second of :func:`song.geometry.lbs.lbs` on a release avatar over 300
  frames, numpy (CPU) against torch on the GPU.
- **closed_loop**: ``song eval --policy depth --resolution 960x540 -j 1`` on the release, steps per
  second, ``gsplat`` against ``numba``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT  # noqa: E402

from song.datasets.bench.load import Benchmark  # noqa: E402
from song.render import GaussianSet, gsplat_backend, render, render_batch, robot_camera  # noqa: E402
from song.runtime.vision import SceneView, scene_gaussians  # noqa: E402

W, H, HFOV, MOUNT = 960, 540, 70.0, 0.8
TARGETS = {"psnr_db": 40.0, "depth_p99_m": 0.01, "alpha_max": 1e-3, "fps_960x540_1m": 100.0}


def _sync() -> None:
    import torch

    if gsplat_backend.DEVICE == "cuda":
        torch.cuda.synchronize()


def _timed(fn, repeats: int) -> float:
    """Median seconds of ``repeats`` calls after one warm-up (CUDA synchronised)."""
    fn()
    _sync()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        _sync()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _compare(ours, theirs) -> dict:
    mse = float(np.mean((ours.rgb.astype(np.float64) - theirs.rgb.astype(np.float64)) ** 2))
    solid = (ours.alpha > 0.5) & (theirs.alpha > 0.5)
    dd = np.abs(ours.depth.astype(np.float64) - theirs.depth.astype(np.float64))[solid]
    return {
        "psnr_db": round(10 * math.log10(255.0**2 / max(mse, 1e-12)), 2),
        "depth_p99_m": round(float(np.percentile(dd, 99)), 5) if dd.size else None,
        "depth_max_m": round(float(dd.max()), 4) if dd.size else None,
        "alpha_max": float(np.abs(ours.alpha - theirs.alpha).max()),
        "alpha_p99": float(np.percentile(np.abs(ours.alpha - theirs.alpha), 99)),
        "alpha_px_over_1e-3": int((np.abs(ours.alpha - theirs.alpha) > 1e-3).sum()),
        "alpha_at_worst": [
            float(a.flat[np.abs(ours.alpha - theirs.alpha).argmax()]) for a in (ours.alpha, theirs.alpha)
        ],
        "coverage": round(float((theirs.alpha > 0.5).mean()), 3),
    }


def _picture(path: Path, ours, theirs) -> None:
    import cv2

    diff = np.clip(10.0 * np.abs(ours.rgb.astype(np.float32) - theirs.rgb.astype(np.float32)), 0, 255)
    row = np.concatenate([theirs.rgb, ours.rgb, diff.astype(np.uint8)], axis=1)
    small = cv2.resize(row, (row.shape[1] // 2, row.shape[0] // 2), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(path), cv2.cvtColor(small, cv2.COLOR_RGB2BGR))


def _views(bench: Benchmark, count: int):
    """(episode, camera pose, t) for the first episodes: the start, facing the nearest pedestrian."""
    out = []
    for ep in list(bench.episodes())[:count]:
        t = float(ep.t0) + 2.0
        x, y = map(float, ep.start_xy)
        yaw, best = float(ep.start_yaw), 8.0
        for track in ep.pedestrians:
            px, py = (float(np.interp(t, track.t, track.xy[:, i])) for i in range(2))
            d = math.hypot(px - x, py - y)
            if 0.8 < d < best:
                yaw, best = math.atan2(py - y, px - x), d
        out.append((ep, (x, y, yaw), t))
    return out


def _placed_avatars(view: SceneView, ep, t: float, pose) -> list[GaussianSet]:
    """Up to five of the episode's avatars posed at ``t``, moved to stand 2–6 m ahead of ``pose``."""
    sets = view.posed_avatars(list(range(min(5, len(ep.pedestrians)))), t)
    x, y, yaw = pose
    placed = []
    for k, g in enumerate(sets):
        dist, off = 2.0 + k, math.radians(-20 + 10 * k)
        means = g.means.copy()
        means[:, :2] += np.array([x + dist * math.cos(yaw + off), y + dist * math.sin(yaw + off)]) - np.median(
            g.means[:, :2], axis=0
        )
        placed.append(GaussianSet(means, g.quats, g.scales, g.opacities, g.sh))
    return placed


def _scene_poses(scene: GaussianSet, count: int) -> list[tuple[float, float, float]]:
    """Cameras around the scene's centre at 3 m, looking at it."""
    centre = np.median(scene.means, axis=0)
    return [
        (float(centre[0] - 3 * math.cos(a)), float(centre[1] - 3 * math.sin(a)), a)
        for a in (2 * math.pi * k / count for k in range(count))
    ]


def parity(bench: Benchmark, scenes: dict[str, Path], out: Path) -> dict:
    view = SceneView("numba")
    result = {}
    first = None
    rows = []
    for ep, pose, t in _views(bench, 4):
        view.reset(ep)
        first = first or (ep, pose, t)
        cam = robot_camera(*pose, MOUNT, HFOV, W, H)
        people = view.posed_avatars(view.visible_pedestrians(_pose(pose), t, 100.0, HFOV), t)
        sets = [view._scenes[ep.gaussians_path], *people]
        ours, theirs = render(sets, cam, "numba"), render(sets, cam, "gsplat")
        rows.append({"episode": ep.episode_id, "avatars": len(people), **_compare(ours, theirs)})
        if len(rows) == 1:
            _picture(out / f"parity_{ep.scene_id}.png", ours, theirs)
    result[f"release:{first[0].scene_id}"] = rows
    ep, pose0, t0 = first
    view.reset(ep)
    for name, ply in scenes.items():
        scene = scene_gaussians(ply)
        rows = []
        for k, pose in enumerate(_scene_poses(scene, 4)):
            cam = robot_camera(*pose, MOUNT, HFOV, W, H)
            sets = [scene, *_placed_avatars(view, ep, t0, pose)]
            ours, theirs = render(sets, cam, "numba"), render(sets, cam, "gsplat")
            rows.append({"view": k, "gaussians": sum(len(s) for s in sets), **_compare(ours, theirs)})
            if k == 0:
                _picture(out / f"parity_{name}.png", ours, theirs)
        result[name] = rows
    flat = [r for rows in result.values() for r in rows]
    result["worst"] = {
        "psnr_db": min(r["psnr_db"] for r in flat),
        "depth_p99_m": max(r["depth_p99_m"] or 0.0 for r in flat),
        "alpha_max": max(r["alpha_max"] for r in flat),
    }
    return result


def _pose(pose):
    from song.runtime.robot import Pose

    return Pose(*pose)


def throughput(bench: Benchmark, scenes: dict[str, Path]) -> dict:
    import torch
    from gsplat import rasterization

    from song.render.gsplat_backend import _gather

    name, ply = max(scenes.items(), key=lambda kv: kv[1].stat().st_size)
    scene = scene_gaussians(ply)
    view = SceneView("numba")
    ep = next(iter(bench.episodes()))
    view.reset(ep)
    poses = _scene_poses(scene, 4)
    avatars = {p: _placed_avatars(view, ep, float(ep.t0) + 2.0, p) for p in poses}
    frame = {"k": 0}

    def one(backend: str) -> None:
        pose = poses[frame["k"] % len(poses)]
        frame["k"] += 1
        sets = [scene, *[GaussianSet(a.means.copy(), a.quats, a.scales, a.opacities, a.sh) for a in avatars[pose]]]
        render(sets, robot_camera(*pose, MOUNT, HFOV, W, H), backend)  # new avatar sets each frame, as a step

    record = {"scene": name, "gaussians": len(scene) + sum(len(a) for a in avatars[poses[0]])}
    record["gsplat_e2e_fps"] = round(1.0 / _timed(lambda: one("gsplat"), 40), 1)
    tensors, degree = _gather([scene, *avatars[poses[0]]])
    cams = [robot_camera(*p, MOUNT, HFOV, W, H) for p in poses]

    def raw(batch: int) -> None:
        chosen = [cams[k % len(cams)] for k in range(batch)]
        views = torch.tensor(np.stack([c.viewmat for c in chosen]), dtype=torch.float32, device=gsplat_backend.DEVICE)
        ks = torch.tensor(np.stack([c.intrinsics for c in chosen]), dtype=torch.float32, device=gsplat_backend.DEVICE)
        means, quats, scales, opacities, sh = tensors
        rasterization(
            means=means, quats=quats, scales=scales, opacities=opacities, colors=sh, viewmats=views, Ks=ks,
            width=W, height=H, near_plane=0.01, far_plane=100.0, eps2d=0.3, sh_degree=degree,
            render_mode="RGB+ED", packed=False, rasterize_mode="classic",
        )  # fmt: skip

    record["gsplat_raster_only_fps"] = round(1.0 / _timed(lambda: raw(1), 40), 1)
    record["gsplat_raster_only_16_cameras_per_s"] = round(16.0 / _timed(lambda: raw(16), 10), 1)
    batch = [cams[k % len(cams)] for k in range(16)]
    sets = [scene, *avatars[poses[0]]]
    record["gsplat_render_batch_16_cameras_per_s"] = round(
        16.0 / _timed(lambda: render_batch(sets, batch, "gsplat"), 5), 1
    )
    start = time.perf_counter()
    for _ in range(3):
        one("numba")
    record["numba_cpu_fps"] = round(3.0 / (time.perf_counter() - start), 2)
    record["numba_threads"] = int(__import__("numba").get_num_threads())
    return record


def lbs_rates(bench: Benchmark) -> dict:
    import torch

    from song.geometry.lbs import lbs, lbs_positions

    view = SceneView("numba")
    ep = next(iter(bench.episodes()))
    view.reset(ep)
    avatar = next(view._avatar(k).posed for k in range(len(ep.pedestrians)) if view._avatar(k).posed is not None)
    transforms = avatar.motion.transforms(slice(0, 300))
    gf = len(avatar.skin) * len(transforms)
    cpu = _timed(lambda: lbs(avatar.skin, transforms), 5)
    skin, block = (
        avatar.skin.to_torch(gsplat_backend.DEVICE),
        torch.from_numpy(np.ascontiguousarray(transforms)).to(gsplat_backend.DEVICE),
    )
    gpu = _timed(lambda: lbs(skin, block), 20)
    gpu_positions = _timed(lambda: lbs_positions(skin, block), 20)
    pos_np, rot_np = lbs(avatar.skin, transforms)
    pos_t, rot_t = lbs(skin, block)
    return {
        "gaussians": len(avatar.skin),
        "frames": len(transforms),
        "numpy_cpu_M_per_s": round(gf / cpu / 1e6, 1),
        "torch_cuda_M_per_s": round(gf / gpu / 1e6, 1),
        "torch_cuda_positions_only_M_per_s": round(gf / gpu_positions / 1e6, 1),
        "max_abs_diff_positions_m": float(np.abs(pos_t.cpu().numpy() - pos_np).max()),
        "max_abs_diff_quats": float(np.abs(np.abs(rot_t.cpu().numpy()) - np.abs(rot_np)).max()),
    }


def closed_loop(bench_path: Path, limit: int) -> dict:
    import pyarrow.parquet as pq

    record = {}
    for backend in ("gsplat", "numba"):
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [sys.executable, "-m", "song", "eval", "--bench", str(bench_path), "--policy", "depth"]
            cmd += ["--resolution", f"{W}x{H}", "--render-backend", backend, "-j", "1", "--limit", str(limit)]
            cmd += ["--out", tmp]
            start = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
            wall = time.perf_counter() - start
            if proc.returncode:
                record[backend] = {"error": proc.stderr.strip().splitlines()[-1:]}
                continue
            steps = int(sum(pq.read_table(Path(tmp) / "depth.parquet").column("steps").to_pylist()))
            record[backend] = {"steps": steps, "wall_s": round(wall, 1), "steps_per_s": round(steps / wall, 2)}
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", type=Path, required=True, help="a release folder")
    parser.add_argument("--scene", action="append", default=[], help="NAME=PLY, more scenes for parity")
    parser.add_argument("--out", type=Path, required=True, help="JSON and pictures go here")
    parser.add_argument("--episodes", type=int, default=2, help="closed-loop episodes per backend")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    scenes = {s.split("=", 1)[0]: Path(s.split("=", 1)[1]) for s in args.scene}
    bench = Benchmark(args.bench)
    record: dict = {}

    def save() -> None:
        (args.out / "gpu.json").write_text(json.dumps(record, indent=1))

    try:
        import torch

        record["device"] = {
            "name": torch.cuda.get_device_name(0) if gsplat_backend.DEVICE == "cuda" else "cpu (stand-in)",
            "torch": torch.__version__,
            "cuda": torch.version.cuda,
            "cpu_count": os.cpu_count(),
        }
        start = time.perf_counter()
        import gsplat

        from song.render.render import gsplat_available

        cam = robot_camera(0.0, 0.0, 0.0, MOUNT, HFOV, 64, 48)
        rng = np.random.default_rng(0)
        tiny = GaussianSet.from_raw(
            rng.uniform([1, -1, 0], [3, 1, 1.5], (64, 3)), rng.normal(size=(64, 4)), np.full((64, 3), -3.0),
            np.zeros(64), np.zeros((64, 3)),
        )  # fmt: skip
        render(tiny, cam, "gsplat")  # the first call compiles gsplat's CUDA code
        record["gsplat"] = {"version": gsplat.__version__, "build_s": round(time.perf_counter() - start, 1)}
        record["gsplat"]["available"] = gsplat_available() or "yes"
    except Exception as exc:
        record["gsplat_error"] = f"{type(exc).__name__}: {exc}"
        traceback.print_exc()
    save()
    sections = [("lbs", lambda: lbs_rates(bench))]
    if "gsplat_error" not in record:
        sections = [
            ("parity", lambda: parity(bench, scenes, args.out)),
            ("throughput", lambda: throughput(bench, scenes)),
            *sections,
            ("closed_loop", lambda: closed_loop(args.bench, args.episodes)),
        ]
    for name, fn in sections:
        start = time.perf_counter()
        try:
            record[name] = fn()
        except Exception as exc:
            record[name] = {"error": f"{type(exc).__name__}: {exc}"}
            traceback.print_exc()
        record.setdefault("section_s", {})[name] = round(time.perf_counter() - start, 1)
        save()
        print(f"{name}: {time.perf_counter() - start:.1f} s", flush=True)
    record["targets"] = TARGETS
    save()
    print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
