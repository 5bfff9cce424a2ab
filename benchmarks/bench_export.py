"""Export of a graded run to a release: wall time, bytes, bytes per episode, open + iterate time.

.venv/bin/python benchmarks/bench_export.py --run runs/e2e/run      # a graded run (e.g. from e2e.py)
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit, folder_bytes, timed  # noqa: E402

import song.datasets.bench as bench  # noqa: E402
from song.datasets.bench.export import export_bench  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--run", type=Path, required=True, help="graded run folder")
    parser.add_argument("--bench", type=Path, default=None, help="where to write (default: a temp folder)")
    args = parser.parse_args()
    os.environ.setdefault("SOURCE_DATE_EPOCH", "1700000000")
    out = args.bench or Path(tempfile.mkdtemp(prefix="song-bench-"))
    record: dict = {"run": str(args.run)}
    try:
        with timed(record, "export_s"):
            result = export_bench(args.run, out, "1.0.0")
        record["episodes"] = result.n_episodes
        record["bytes"] = folder_bytes(result.path)
        record["bytes_per_episode"] = round(record["bytes"] / max(1, result.n_episodes))
        with timed(record, "open_iterate_s"):
            release = bench.open(out)
            record["iterated"] = sum(1 for _ in release.episodes())
        record["fingerprint"] = result.fingerprint
    finally:
        if args.bench is None:
            shutil.rmtree(out, ignore_errors=True)
    emit(record)


if __name__ == "__main__":
    main()
