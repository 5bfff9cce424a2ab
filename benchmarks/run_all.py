"""Run every benchmark once, one after the other, and keep what each printed: the run behind benchmarks/README.md.

    .venv/bin/python benchmarks/run_all.py [--out benchmarks/results] [--only NAME ...] [--skip NAME ...]

Each benchmark runs alone (nothing else of ours beside it), in the order below; for each the script
records its command, the date, the 1-minute load average before it started, its wall time, its exit
status and the JSON object it printed (or the tail of its output when it printed none) in
``<out>/<name>.json``, and a summary in ``<out>/index.json``. A benchmark that needs what this machine
lacks (a GPU, the demo release ``runs/demo-bench`` from ``make demo``) is recorded as skipped with the
reason. The 500-scene end-to-end run takes ~15 minutes; ``--skip e2e_500`` leaves it out.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT  # noqa: E402

DEMO = "runs/demo-bench"
# name → (arguments, what it needs: "demo" for the demo release, "gpu" for a CUDA device)
BENCHMARKS: dict[str, tuple[list[str], tuple[str, ...]]] = {
    "scenes": (["scenes.py", "--count", "100"], ()),
    "clutter": (["clutter.py"], ()),
    "lighting": (["lighting.py"], ()),
    "near_field": (["near_field.py"], ()),
    "avatar_pool": (["avatar_pool.py"], ()),
    "intents": (["intents.py"], ()),
    "navmesh": (["navmesh.py", "--recast"], ()),
    "orca": (["orca.py"], ()),
    "crowd": (["crowd.py"], ()),
    "crowd_realism": (
        [
            "crowd_realism.py",
            "--generated",
            "20",
            "--avoidance",
            "orca",
            "--speed-profile",
            "paper",
            "human",
            "--seeds",
            *[str(s) for s in range(1, 13)],
            "--markdown",
        ],
        (),
    ),
    "crowd_density": (["crowd_density.py"], ()),
    "motion": (["motion.py", "--quick"], ()),
    "motion_normative": (["motion.py", "--quick", "--normative"], ()),
    "postures": (["postures.py"], ()),
    "binding": (["binding.py"], ()),
    "stages": (["stages.py"], ()),
    "grading": (["grading.py"], ()),
    "episodes": (["episodes.py", "--run", "runs/demo"], ("demo",)),
    "bench_export": (["bench_export.py", "--run", "runs/demo"], ("demo",)),
    "runtime": (["runtime.py", "--episodes", "10"], ()),
    "render": (["render.py", "--frames", "8"], ()),
    "threading_layers": (["threading_layers.py", "--frames", "10", "--rounds", "2"], ()),
    "render_layers": (["render_layers.py", "--bench", DEMO], ("demo",)),
    "batched_cameras": (["batched_cameras.py", "--bench", DEMO], ("demo",)),
    "closed_loop": (["closed_loop.py", "--bench", DEMO, "--episodes", "12"], ("demo",)),
    "gym_env": (["gym_env.py", "--bench", DEMO], ("demo",)),
    "collect": (["collect.py", "--bench", DEMO, "--limit", "12", "--workers", "2"], ("demo",)),
    "camera": (["camera.py", "--bench", DEMO], ("demo",)),
    "reactive": (["reactive.py", "--bench", DEMO, "--episodes", "40"], ("demo",)),
    "trust": (["trust.py", "--bench", DEMO], ("demo",)),
    "people": (["people.py", "--bench", DEMO, "--body", "80", "--faces", "48"], ("demo",)),
    "teleop": (["teleop.py", "--bench", DEMO, "--episode", "procthor_house_6-001"], ("demo",)),
    "gpu": (["gpu.py"], ("gpu",)),
    "e2e_60": (
        ["e2e.py", "--scenes", "60", "--episodes", "60", "--workers", "2", "--splat", "--out", "runs/e2e60"],
        (),
    ),
    "e2e_500": (
        ["e2e.py", "--scenes", "500", "--episodes", "500", "--workers", "2", "--splat", "--out", "runs/e2e500"],
        (),
    ),
}


def _missing(needs: tuple[str, ...]) -> str:
    """Why this machine cannot run a benchmark ("" when it can)."""
    if "demo" in needs and not any((ROOT / DEMO).glob("*/meta/info.json")):
        return f"needs the demo release {DEMO} (make demo)"
    if "gpu" in needs:
        try:
            import torch

            if torch.cuda.is_available():
                return ""
        except ImportError:
            pass
        return "needs a CUDA device"
    return ""


def _json_of(text: str) -> dict | None:
    """The last JSON object a script printed (scripts print one; --markdown adds tables after it)."""
    start = text.find("{")
    while start >= 0:
        try:
            return json.JSONDecoder().raw_decode(text[start:])[0]
        except ValueError:
            start = text.find("{", start + 1)
    return None


def run_one(name: str, out: Path) -> dict:
    args, needs = BENCHMARKS[name]
    command = ["python", f"benchmarks/{args[0]}", *args[1:]]
    record = {
        "name": name,
        "command": " ".join(command),
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "load_1min_before": round(os.getloadavg()[0], 2),
    }
    why = _missing(needs)
    if why:
        record.update(status="skipped", reason=why)
    else:
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, *command[1:]], cwd=ROOT, capture_output=True, text=True)
        record["wall_s"] = round(time.perf_counter() - start, 1)
        record["status"] = "ok" if proc.returncode == 0 else f"exit {proc.returncode}"
        record["result"] = _json_of(proc.stdout)
        if record["result"] is None or proc.returncode != 0:
            record["output_tail"] = (proc.stdout + proc.stderr)[-3000:]
        if "--markdown" in args:
            record["markdown"] = proc.stdout[proc.stdout.rfind("}") + 1 :].strip()
    (out / f"{name}.json").write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    parser.add_argument("--only", nargs="*", default=None, help="run only these (names as in BENCHMARKS)")
    parser.add_argument("--skip", nargs="*", default=[], help="leave these out")
    args = parser.parse_args()
    unknown = (set(args.only or []) | set(args.skip)) - set(BENCHMARKS)
    if unknown:
        parser.error(f"unknown benchmark(s) {sorted(unknown)}; known: {', '.join(BENCHMARKS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    names = [n for n in (args.only or BENCHMARKS) if n not in args.skip]
    index_path = args.out / "index.json"
    index = json.loads(index_path.read_text()) if index_path.is_file() else {}
    for name in names:
        record = run_one(name, args.out)
        index[name] = {k: record.get(k) for k in ("command", "date", "load_1min_before", "wall_s", "status", "reason")}
        index_path.write_text(json.dumps(index, indent=2, sort_keys=True) + "\n")
        print(f"{name}: {record['status']} {record.get('wall_s', '')}", flush=True)  # noqa: T201


if __name__ == "__main__":
    main()
