"""Scene packages: geometry generation, Gaussian scene synthesis per scene, ProcTHOR import.

    .venv/bin/python benchmarks/scenes.py [--count 100] [--spacing 0.035] [--repeat 3]

Prints JSON:
- ``generate``: procedural packages without Gaussians (semantic map, occupancy, USD proxy): seconds
  and MB per scene over ``--count`` scenes;
- ``splat``: per scene of the 8 procedural samples (``--seed 7``) and the 3 ProcTHOR sample houses
  (read from ../shared; skipped with a reason when absent): Gaussians, PLY MB, best-of-``--repeat``
  seconds of ``dress_package`` (Gaussians + USD proxy written) and seconds per million Gaussians.
  Targets (issue 17): ≤ 20 MB and ≤ 2 s on 2 cores per million Gaussians;
- ``procthor``: objects kept and objects that could not be sized, per house.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit, folder_bytes  # noqa: E402

from song.datasets.scenes import load_scene_package  # noqa: E402
from song.datasets.scenes.generate import generate_scenes  # noqa: E402
from song.datasets.scenes.procthor import import_procthor  # noqa: E402
from song.datasets.scenes.splat import SPACING_M, dress_package  # noqa: E402

HOUSES = ROOT.parent / "shared" / "sample_scenes" / "procthor_houses"


def _splat_rows(roots: list[Path], spacing: float, repeat: int) -> dict:
    rows = {}
    for root in roots:
        best = float("inf")
        for _ in range(repeat):
            start = time.perf_counter()
            result = dress_package(root, spacing=spacing)
            best = min(best, time.perf_counter() - start)
        rows[root.name] = {
            "gaussians": result.gaussians,
            "ply_mb": round(result.ply_mb, 2),
            "usd_kb": round(result.usd_kb, 1),
            "seconds": round(best, 3),
            "s_per_million": round(best / result.gaussians * 1e6, 3),
            "mb_per_million": round(result.ply_mb / result.gaussians * 1e6, 2),
        }
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=100)
    parser.add_argument("--spacing", type=float, default=SPACING_M)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="song-scenes-"))
    record: dict = {"spacing_m": args.spacing}
    try:
        start = time.perf_counter()
        generate_scenes(args.count, 0, tmp / "gen", splat=False)
        wall = time.perf_counter() - start
        sizes = [folder_bytes(p) for p in (tmp / "gen").iterdir()]
        record["generate"] = {
            "count": args.count,
            "s_per_scene": round(wall / args.count, 4),
            "mb_per_scene_mean": round(float(np.mean(sizes)) / 1e6, 3),
            "mb_per_scene_max": round(float(np.max(sizes)) / 1e6, 3),
        }
        roots = generate_scenes(8, 7, tmp / "samples", splat=False)
        if HOUSES.is_dir():
            results = import_procthor(HOUSES, tmp / "samples", splat=False)
            roots += [r.path for r in results if r.path is not None]
            record["procthor"] = {
                r.scene_id: {
                    "objects": len(load_scene_package(r.path).semantic_map.objects) if r.path else 0,
                    "unsized": r.unsized,
                    "error": r.error,
                }
                for r in results
            }
        else:
            record["procthor"] = f"skipped: {HOUSES} is absent (third-party houses live in ../shared)"
        rows = _splat_rows(roots, args.spacing, args.repeat)
        record["splat"] = rows
        per_million = [r["s_per_million"] for r in rows.values()]
        record["splat_summary"] = {
            "gaussians_min": min(r["gaussians"] for r in rows.values()),
            "gaussians_max": max(r["gaussians"] for r in rows.values()),
            "ply_mb_max": max(r["ply_mb"] for r in rows.values()),
            "mb_per_million_max": max(r["mb_per_million"] for r in rows.values()),
            "s_per_million_median": round(float(np.median(per_million)), 3),
            "s_per_million_max": max(per_million),
        }
        record["targets"] = {"mb_per_million": 20.0, "s_per_million": 2.0}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    emit(record)


if __name__ == "__main__":
    main()
