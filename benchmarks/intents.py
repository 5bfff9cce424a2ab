"""Offline intents + filtering per scene: time, kept ratio and rejection reasons (JSON).

.venv/bin/python benchmarks/intents.py [--scenes datasets/sample_scenes]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import SongConfig  # noqa: E402
from song.datasets.scenes import find_scene_packages, load_scene_package  # noqa: E402
from song.pipeline.intents import generate_intents  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", type=Path, default=ROOT / "datasets" / "sample_scenes")
    args = parser.parse_args()
    config = SongConfig(intents={"llm": "offline"})
    per_scene, times = {}, []
    for root in find_scene_packages(args.scenes):
        package = load_scene_package(root)
        generate_intents(package, config, np.random.default_rng(0))  # warm caches (imports)
        start = time.perf_counter()
        result = generate_intents(package, config, np.random.default_rng(0))
        times.append(1000 * (time.perf_counter() - start))
        proposed = len(result.intents) + len(result.rejected)
        per_scene[package.scene_id] = {
            "ms": round(times[-1], 1),
            "kept": len(result.intents),
            "proposed": proposed,
            "kept_ratio": round(len(result.intents) / max(1, proposed), 3),
            "rejections": dict(Counter(r.reason for r in result.rejected)),
        }
    emit({"median_ms": round(float(np.median(times)), 1), "target_median_ms": 50, "scenes": per_scene})


if __name__ == "__main__":
    main()
