"""Imitation-data throughput: steps per second of ``song collect`` with depth at 320×240 on 2 workers.

    .venv/bin/python benchmarks/collect.py --bench runs/demo-bench [--limit 12] [--workers 2]

Runs ``song collect --split test --limit N --keep all --sensors state,depth --resolution 320x240 -j W``
with the ``social`` expert on the release (every rollout kept, so the count does not depend on the
outcomes) into a temporary folder, and reports the recorded steps (the LeRobot dataset's
``meta/info.json`` ``total_frames``), the wall time of the whole command (start-up, rendering, video
encoding and writing included) and steps per second. The issue's target is ≥ 12 steps/s on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", required=True)
    parser.add_argument("--limit", type=int, default=12)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--resolution", default="320x240")
    args = parser.parse_args()
    out = Path(tempfile.mkdtemp(prefix="song-collect-")) / "dataset"
    command = [
        sys.executable, "-m", "song", "collect", "--bench", args.bench, "--out", str(out), "--split", "test",
        "--limit", str(args.limit), "--keep", "all", "--sensors", "state,depth", "--resolution", args.resolution,
        "-j", str(args.workers),
    ]  # fmt: skip
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        emit({"error": (proc.stdout + proc.stderr)[-2000:]})
        sys.exit(1)
    info = json.loads((out / "meta" / "info.json").read_text())
    steps = int(info["total_frames"])
    shutil.rmtree(out.parent, ignore_errors=True)
    emit(
        {
            "bench": args.bench,
            "episodes": int(info["total_episodes"]),
            "steps": steps,
            "wall_s": round(wall, 2),
            "steps_per_s": round(steps / wall, 2),
            "resolution": args.resolution,
            "workers": args.workers,
            "load_1min_start": round(load, 2),
            "target_steps_per_s": 12,
        }
    )


if __name__ == "__main__":
    main()
