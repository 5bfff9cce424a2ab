"""Binding and LBS figures (issue #6), one JSON object.

.venv/bin/python benchmarks/binding.py [--quick] [--avatars DIR]

- LBS throughput, Gaussian-frames per second: positions only (what the runtime needs) and positions +
  rotations, numpy and torch (CPU), on a 20k-Gaussian avatar over a block of frames of a real motion;
- binding stage per sample scene (intents → crowd → motion run once on the shipped samples, then only
  the binding stage timed) with the default pool (20k Gaussians per avatar; built once, cached);
- compact cache bytes per pedestrian-minute over every pedestrian, and materialised bytes for one;
- ``pose_avatars`` for 5 pedestrians × 20k Gaussians at one time t (median of repeats).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import BindingConfig, SongConfig  # noqa: E402
from song.datasets.avatars import load_avatar  # noqa: E402
from song.datasets.avatars.cache import (  # noqa: E402
    PosedAvatar,
    load_compact_cache,
    pose_avatars,
    skin_asset,
    write_materialized_cache,
)
from song.geometry.lbs import lbs, lbs_positions  # noqa: E402
from song.pipeline.binding.pool import ensure_pool  # noqa: E402
from song.pipeline.chain import iter_run  # noqa: E402

SAMPLES = ROOT / "datasets" / "sample_scenes"
TARGETS = {"lbs_positions_numpy": 20e6, "binding_s_per_scene_median": 1.0, "compact_kb_per_ped_minute": 200.0}


def _rate(fn, gaussian_frames: int, repeats: int) -> float:
    """Gaussian-frames per second of the median call (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return gaussian_frames / float(np.median(times))


def lbs_throughput(avatar: PosedAvatar, frames: int, repeats: int) -> dict:
    transforms = avatar.motion.transforms(slice(0, frames))
    gf = len(avatar.skin) * len(transforms)
    out = {
        "lbs_positions_numpy": _rate(lambda: lbs_positions(avatar.skin, transforms), gf, repeats),
        "lbs_full_numpy": _rate(lambda: lbs(avatar.skin, transforms), gf, repeats),
    }
    try:
        import torch
    except ImportError:
        return out
    skin, block = avatar.skin.to_torch(), torch.from_numpy(transforms)
    out["lbs_positions_torch"] = _rate(lambda: lbs_positions(skin, block), gf, repeats)
    out["lbs_full_torch"] = _rate(lambda: lbs(skin, block), gf, repeats)
    out["torch_threads"] = torch.get_num_threads()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    parser.add_argument("--avatars", type=Path, default=None, help="pool folder (default: the cached default pool)")
    args = parser.parse_args()
    binding = BindingConfig(avatars_dir=str(args.avatars or ""))
    start = time.perf_counter()
    pool = ensure_pool(binding)
    pool_s = time.perf_counter() - start
    config = SongConfig(seed=0, binding=binding)
    result: dict = {"pool": {"assets": len(pool), "gaussians": len(load_avatar(pool[0])), "ready_s": round(pool_s, 2)}}
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        upstream = list(iter_run(SAMPLES, run, config, ["intents", "crowd", "motion"], executor="serial"))
        scenes = [r.scene_id for r in upstream if r.status == "ok"]
        per_scene = []
        for scene_id in scenes:
            t = time.perf_counter()
            [res] = list(iter_run(SAMPLES, run, config, ["binding"], executor="serial", scene_ids=[scene_id]))
            per_scene.append(time.perf_counter() - t)
            assert res.status == "ok", res.error
        caches = sorted(run.glob("scenes/*/binding/traj_*.npz"))
        minutes = [len(load_compact_cache(p)) / 30.0 / 60.0 for p in caches]
        kb = [p.stat().st_size / 1000 / m for p, m in zip(caches, minutes, strict=True)]
        first = load_compact_cache(caches[0])
        asset = load_avatar(pool[0])
        avatars = [PosedAvatar.load(asset, load_compact_cache(p)) for p in caches[:5]]
        materialized = Path(tmp) / "m.npz"
        write_materialized_cache(materialized, asset.scaled(first.meta["scale"]), first)
        frames = 60 if args.quick else 300
        result["lbs_gaussian_frames_per_s"] = lbs_throughput(avatars[0], frames, 3 if args.quick else 11)
        t_mid = float(first.frame0 + len(first) // 2) / first.fps
        times = []
        for _ in range(5 if args.quick else 30):
            t = time.perf_counter()
            pose_avatars(avatars, t_mid)
            times.append(time.perf_counter() - t)
        result.update(
            {
                "scenes": len(scenes),
                "pedestrians": len(caches),
                "binding_s_per_scene_median": round(float(np.median(per_scene)), 3),
                "binding_s_per_scene_max": round(float(np.max(per_scene)), 3),
                "compact_kb_per_ped_minute": round(float(np.median(kb)), 1),
                "compact_kb_per_ped_minute_max": round(float(np.max(kb)), 1),
                "materialized_mb_per_ped_minute": round(materialized.stat().st_size / 1e6 / (len(first) / 1800.0), 1),
                "pose_avatars_5x_ms_median": round(1000 * float(np.median(times)), 2),
                "skin_prepare_ms": round(_prepare_ms(asset), 2),
            }
        )
    lbs_rate = result["lbs_gaussian_frames_per_s"]
    result["targets_met"] = {
        "lbs_positions_numpy>=20M/s": lbs_rate["lbs_positions_numpy"] >= TARGETS["lbs_positions_numpy"],
        "lbs_full_numpy>=20M/s": lbs_rate["lbs_full_numpy"] >= TARGETS["lbs_positions_numpy"],
        "binding<=1s/scene": result["binding_s_per_scene_median"] <= TARGETS["binding_s_per_scene_median"],
        "compact<=200KB/ped-min": result["compact_kb_per_ped_minute"] <= TARGETS["compact_kb_per_ped_minute"],
        "pose_5x20k<=10ms": result["pose_avatars_5x_ms_median"] <= 10.0,
    }
    result["lbs_gaussian_frames_per_s"] = {k: round(v / 1e6, 1) if "lbs" in k else v for k, v in lbs_rate.items()}
    result["units"] = {"lbs_gaussian_frames_per_s": "millions per second"}
    emit(result)


def _prepare_ms(asset) -> float:
    t = time.perf_counter()
    skin_asset(asset)
    return 1000 * (time.perf_counter() - t)


if __name__ == "__main__":
    main()
