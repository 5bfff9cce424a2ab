"""End to end at scale: N procedural scenes → synth → grade (500 episodes) → export.

    .venv/bin/python benchmarks/e2e.py [--scenes 500] [--episodes 500] [--workers 2] [--out runs/e2e]

Prints wall time per stage, CPU seconds per scene, peak RSS (driver and workers) and output bytes.
Targets (issue 10): ≤ 10 minutes wall on 2 cores for 500 scenes with the offline LLM and the
procedural gait; peak RSS ≤ 4 GB.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_seconds, emit, folder_bytes, peak_rss_mb  # noqa: E402

SONG = [sys.executable, "-m", "song"]


def run(step: str, args: list[str], record: dict) -> None:
    start = time.perf_counter()
    proc = subprocess.run([*SONG, *args], capture_output=True, text=True)
    record[f"{step}_s"] = round(time.perf_counter() - start, 2)
    if proc.returncode != 0:
        record[f"{step}_error"] = (proc.stdout + proc.stderr)[-2000:]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", type=int, default=500)
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("runs/e2e"))
    parser.add_argument("--keep", action="store_true", help="keep an existing run (resume) instead of starting over")
    parser.add_argument(
        "--splat",
        action="store_true",
        help="also synthesise each scene's Gaussians (1.3-1.9 s and 9-17 MB per scene, copied into the release); "
        "off by default: the budget covers synth, grade and export of the scenes given",
    )
    args = parser.parse_args()
    os.environ.setdefault("SOURCE_DATE_EPOCH", "1700000000")
    if args.out.exists() and not args.keep:
        shutil.rmtree(args.out)
    scenes, run_dir, bench = args.out / "scenes", args.out / "run", args.out / "bench"
    record: dict = {"scenes": args.scenes, "episodes": args.episodes, "workers": args.workers, "splat": args.splat}
    cpu0 = cpu_seconds()
    total = time.perf_counter()
    run(
        "generate",
        [
            "scenes",
            "generate",
            "--count",
            str(args.scenes),
            "--seed",
            str(args.seed),
            "--out",
            str(scenes),
            "--workers",
            str(args.workers),
        ]
        + ([] if args.splat else ["--no-splat"]),
        record,
    )
    run(
        "synth",
        ["synth", "--scenes", str(scenes), "--out", str(run_dir), "--workers", str(args.workers), "--quiet"],
        record,
    )
    run(
        "grade",
        ["grade", "--run", str(run_dir), "--episodes", str(args.episodes), "--workers", str(args.workers)],
        record,
    )
    shutil.rmtree(bench, ignore_errors=True)
    run("export", ["export-bench", "--run", str(run_dir), "--bench", str(bench), "--version", "1.0.0"], record)
    record["total_s"] = round(time.perf_counter() - total, 2)
    record["cpu_s_per_scene"] = round((cpu_seconds() - cpu0) / max(1, args.scenes), 3)
    record["peak_rss_mb"] = peak_rss_mb()
    record["run_bytes"] = folder_bytes(run_dir) if run_dir.exists() else 0
    record["bench_bytes"] = folder_bytes(bench) if bench.exists() else 0
    record["target_total_s"] = 600
    emit(record)


if __name__ == "__main__":
    main()
