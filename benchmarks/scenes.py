"""Scene packages: procedural generation time and size per package; ProcTHOR import and connectivity.

.venv/bin/python benchmarks/scenes.py [--count 100]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit, folder_bytes  # noqa: E402

from song.datasets.scenes import load_scene_package  # noqa: E402
from song.datasets.scenes.generate import generate_scenes  # noqa: E402
from song.datasets.scenes.procthor import import_procthor  # noqa: E402
from song.geometry.freespace import erode  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=100)
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="song-scenes-"))
    try:
        start = time.perf_counter()
        generate_scenes(args.count, 0, tmp / "gen")
        wall = time.perf_counter() - start
        sizes = [folder_bytes(p) for p in (tmp / "gen").iterdir()]
        start = time.perf_counter()
        results = import_procthor(ROOT / "tests" / "data" / "procthor_houses", tmp / "pt")
        import_s = time.perf_counter() - start
        houses = {}
        for r in results:
            package = load_scene_package(r.path)
            grid = package.occupancy
            legal = erode(grid.free, grid.resolution, 0.25)
            _, parts = ndimage.label(legal, structure=np.ones((3, 3)))
            houses[r.scene_id] = {
                "free_m2": round(float(grid.free.sum()) * grid.resolution**2, 1),
                "walkable_parts": int(parts),
            }
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    emit(
        {
            "generate_count": args.count,
            "generate_s": round(wall, 2),
            "generate_s_per_scene": round(wall / args.count, 4),
            "mb_per_scene_mean": round(float(np.mean(sizes)) / 1e6, 3),
            "mb_per_scene_max": round(float(np.max(sizes)) / 1e6, 3),
            "targets": {"s_per_scene": 0.3, "mb_per_scene": 2.0},
            "procthor_import_s": round(import_s, 3),
            "procthor_houses": houses,
        }
    )


if __name__ == "__main__":
    main()
