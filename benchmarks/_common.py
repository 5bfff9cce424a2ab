"""Helpers shared by the benchmark scripts: timing, peak memory, JSON output."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

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


def give_up_dither(xy, ids, status: dict, intents, mesh, fps: int) -> list[tuple[float, float]]:
    """Per walker that gave its routine up: (seconds it got no nearer its goal before giving up, metres walked then).

    ``xy`` (N, F, 2) are the tracks of pedestrians ``ids`` from t = 0, ``status`` their ``crowd_status.json``
    entries by id (int or str keys), ``intents`` the scene's (their routines' last stops). Nearer: 10 cm less path to
    the goal on the static navmesh (a straight line would count a detour round a wall as none), than
    anywhere since it set off on that last leg (``last_leg_s``; from t = 0 in files without it). The
    dither the crowd issue asks to end within 5 s.
    """
    goals = {int(i.id): np.asarray(i.route()[-1].goal_xy, dtype=np.float64) for i in intents}  # the last stop
    out = []
    for row, k in enumerate(int(i) for i in ids):
        info = status.get(k, status.get(str(k)))
        if info is None or info["status"] != "gave_up":
            continue
        end = int(round(info["gave_up_s"] * fps))
        track = xy[row, max(int(round((info.get("last_leg_s") or 0.0) * fps)), 0) : end + 1]
        gap = np.array([mesh.find_path(p, goals[k], max_snap=0.5, allow_partial=True).length for p in track])
        best = np.minimum.accumulate(gap)
        behind = np.flatnonzero(best > best[-1] + 0.1)  # frames before its last 10 cm of progress
        start = behind[-1] + 1 if len(behind) else 0
        out.append(((len(track) - 1 - start) / fps, float(np.hypot(*np.diff(track[start:], axis=0).T).sum())))
    return out


def dither_summary(dither: list[tuple[float, float]]) -> dict:
    """Median and maximum of :func:`give_up_dither`'s seconds, median metres, and the share within 5 s."""
    if not dither:
        return {"give_up_walkers": 0}
    stuck, walked = np.array([s for s, _ in dither]), np.array([m for _, m in dither])
    return {
        "give_up_walkers": len(dither),
        "give_up_no_progress_s_median": round(float(np.median(stuck)), 1),
        "give_up_no_progress_s_max": round(float(stuck.max()), 1),
        "give_up_within_5s_share": round(float(np.mean(stuck <= 5.0)), 4),
        "give_up_walked_m_median": round(float(np.median(walked)), 1),
    }
