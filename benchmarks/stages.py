"""Per-scene stage timings on the shipped sample scenes (intents, crowd, motion, binding), one JSON object.

.venv/bin/python benchmarks/stages.py

Runs the whole chain serially (one process, so each figure is one scene's own time) into a scratch
folder and reports per stage the median and maximum seconds per scene, plus crowd arrivals. The default
avatar pool is built (or reused) before timing.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, crowd_outcomes, emit  # noqa: E402

from song.config import SongConfig  # noqa: E402
from song.pipeline.binding.pool import ensure_pool  # noqa: E402
from song.pipeline.chain import iter_run  # noqa: E402

TARGETS = {"intents": 0.05, "crowd": 0.5, "binding": 1.0}


def main() -> None:
    config = SongConfig()
    ensure_pool(config.binding)
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        results = list(iter_run(ROOT / "datasets" / "sample_scenes", run, config, executor="serial"))
        statuses = [
            v for p in sorted(run.glob("scenes/*/crowd_status.json")) for v in json.loads(p.read_text()).values()
        ]
    stages = sorted({name for r in results for name in r.seconds})
    per_stage = {
        name: {
            "median_s": round(float(np.median([r.seconds[name] for r in results if name in r.seconds])), 3),
            "max_s": round(float(np.max([r.seconds[name] for r in results if name in r.seconds])), 3),
        }
        for name in stages
    }
    emit(
        {
            "scenes": len(results),
            "failed": [r.scene_id for r in results if r.status != "ok"],
            "stage_seconds_per_scene": per_stage,
            **crowd_outcomes(statuses),
            "targets_median_s": TARGETS,
        }
    )


if __name__ == "__main__":
    main()
