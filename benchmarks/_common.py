"""Helpers shared by the benchmark scripts: timing, peak memory, JSON output."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@contextmanager
def timed(record: dict, key: str):
    """Store wall seconds of the block in ``record[key]``."""
    start = time.perf_counter()
    yield
    record[key] = round(time.perf_counter() - start, 3)


def peak_rss_mb(children: bool = True) -> float:
    """Peak resident memory of this process (and of its finished children), MB."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss if children else 0
    return round(max(own, kids) / 1024, 1)


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and its finished children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in Path(path).rglob("*") if p.is_file())


def emit(result: dict) -> None:
    """Print the one JSON object a benchmark script reports."""
    json.dump(result, sys.stdout, indent=2, sort_keys=True)
    sys.stdout.write("\n")


def crowd_outcomes(statuses: list[dict]) -> dict:
    """Shares of a crowd's pedestrians (``crowd_status.json`` values) by outcome, and the stops given up.

    ``arrived``: reached the last stop of the routine; ``routine_complete``: reached it without giving
    up a stop on the way; ``gave_up``: stalled for good on the last leg (it stands out of the way);
    ``removed``: could not start (``timeout`` is the rest).
    """
    total = max(len(statuses), 1)
    arrived = [s for s in statuses if s["status"] == "arrived"]
    return {
        "arrived_share": round(len(arrived) / total, 4),
        "routine_complete_share": round(sum(not s.get("skipped_stops") for s in arrived) / total, 4),
        "gave_up_share": round(sum(s["status"] == "gave_up" for s in statuses) / total, 4),
        "removed_share": round(sum(s["status"] == "removed" for s in statuses) / total, 4),
        "stops_skipped": sum(len(s.get("skipped_stops", [])) for s in statuses),
        "pedestrians": len(statuses),
    }


def bench_env(env: Path, probe: str, packages: list[str]) -> Path:
    """The Python of a benchmark's own environment at ``env`` (created with ``packages`` on first use).

    Reference tools that judge our output live in such environments, never in ``song``'s own.
    ``probe`` is Python code that succeeds once the environment is ready (e.g. ``"import bpy"``).
    """
    python = env / "bin" / "python"
    if python.is_file() and subprocess.run([str(python), "-c", probe], capture_output=True).returncode == 0:
        return python
    subprocess.run([sys.executable, "-m", "venv", str(env)], check=True)
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", *packages], check=True)
    return python
