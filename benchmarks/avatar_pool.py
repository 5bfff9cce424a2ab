"""Cost of building the default avatar pool, per body (Anny and procedural), each in a fresh interpreter.

    python benchmarks/avatar_pool.py [--count 128] [--gaussians 40000]

Prints JSON: wall and CPU seconds for ``build_pool`` (the Anny model's one-time load is reported
apart and included in the wall time), MB per identity on disk, and the child's peak RSS.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile

from _common import ROOT, emit

CHILD = """
import json, resource, sys, time
from pathlib import Path
t0 = time.perf_counter(); c0 = time.process_time()
from song.datasets.avatars.generate import build_pool
body = sys.argv[1]
load = 0.0
if body == "anny":
    from song.datasets.avatars import body_model
    t = time.perf_counter(); body_model._load(); load = time.perf_counter() - t
paths = build_pool(Path(sys.argv[2]), int(sys.argv[3]), 0, int(sys.argv[4]), body=body)
size = sum(p.stat().st_size for p in paths)
print(json.dumps({"body": body, "wall_s": round(time.perf_counter() - t0, 2), "cpu_s": round(time.process_time() - c0, 2),
    "model_load_s": round(load, 2), "mb_per_identity": round(size / len(paths) / 1e6, 3),
    "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=128)
    parser.add_argument("--gaussians", type=int, default=40_000)
    args = parser.parse_args()
    from song.datasets.avatars.body_model import available

    rows = []
    for body in ("anny", "procedural") if available() else ("procedural",):
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run(
                [sys.executable, "-c", CHILD, body, tmp, str(args.count), str(args.gaussians)],
                capture_output=True,
                text=True,
                check=True,
                cwd=ROOT,
            )
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    emit({"count": args.count, "gaussians": args.gaussians, "bodies": rows})


if __name__ == "__main__":
    main()
