"""numba's threading layers for the renderer on a shared machine: FPS under background load, interleaved.

    .venv/bin/python benchmarks/threading_layers.py [--loads 0 2 4] [--frames 12] [--rounds 2]

Each measurement is a fresh process (the layer is fixed at numba's first parallel launch) that renders
``--frames`` robot-camera frames at 320×240 of a procedural office at 5.2 cm spacing (~300 k Gaussians)
with five pool avatars, after two warm-up frames, while ``load`` other processes spin on the CPU. Layers:
``omp`` with ``OMP_WAIT_POLICY=PASSIVE``, ``omp`` as it comes (GNU OpenMP spins before sleeping),
``workqueue``, and ``tbb`` when the ``tbb`` package is installed. Reported per load and layer: the median
FPS over the rounds and the renderer's CPU seconds per frame (process time, all threads).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

LAYERS = {
    "omp_passive": {"NUMBA_THREADING_LAYER": "omp", "OMP_WAIT_POLICY": "PASSIVE"},
    "omp": {"NUMBA_THREADING_LAYER": "omp"},
    "workqueue": {"NUMBA_THREADING_LAYER": "workqueue"},
    # PyPI's tbb puts libtbb.so.12 in the environment's lib/, which the loader does not search by itself
    "tbb": {"NUMBA_THREADING_LAYER": "tbb", "LD_LIBRARY_PATH": str(Path(sys.prefix) / "lib")},
}


def worker(scene: Path, frames: int) -> None:
    import math

    import numba
    import numpy as np
    from render import _avatars, _place, _procedural_poses  # benchmarks/render.py's scene helpers

    from song.render import render, robot_camera
    from song.runtime.vision import scene_gaussians

    gaussians = scene_gaussians(scene / "3dgs_compressed.ply")
    avatars = _avatars()
    poses = _procedural_poses(scene, 4)
    times, cpu = [], []
    for k in range(frames + 2):
        x, y, yaw = poses[k % len(poses)]
        camera = robot_camera(x, y, yaw, 0.8, 70.0, 320, 240)
        sets = [gaussians, *_place(avatars, x, y, yaw)]
        start, start_cpu = time.perf_counter(), time.process_time()
        render(sets, camera, "numba")
        if k >= 2:
            times.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
    print(json.dumps({"layer": numba.threading_layer(), "fps": 1.0 / float(np.median(times)),
                      "cpu_s": float(np.median(cpu)), "threads": numba.get_num_threads(),
                      "finite": bool(math.isfinite(float(np.median(times))))}))  # fmt: skip


def _measure(layer: str, scene: Path, frames: int, load: int) -> dict:
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(load)]
    try:
        env = {**os.environ, **LAYERS[layer]}
        env.pop("OMP_WAIT_POLICY", None) if layer != "omp_passive" else None
        cmd = [sys.executable, __file__, "--worker", str(scene), "--frames", str(frames)]
        done = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    if done.returncode:
        return {"error": (done.stderr.strip().splitlines() or ["?"])[-1][:200]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", type=Path, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--loads", type=int, nargs="+", default=[0, 2, 4])
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, args.frames)
        return
    import numpy as np

    from song.datasets.scenes.generate import generate_scene

    has_tbb = any((Path(sys.prefix) / "lib").glob("libtbb.so*"))  # PyPI's tbb ships the library, no module
    layers = [name for name in LAYERS if name != "tbb" or has_tbb]
    scene = generate_scene("office_0000", "office", 7, Path(tempfile.mkdtemp(prefix="song-layers-")), True, 0.052)
    record: dict = {"cpu_count": os.cpu_count(), "frames": args.frames, "rounds": args.rounds, "layers": layers}
    for load in args.loads:
        runs: dict[str, list[dict]] = {name: [] for name in layers}
        for _ in range(args.rounds):
            for name in layers:  # interleaved: the machine is shared
                runs[name].append(_measure(name, scene, args.frames, load))
        record[f"load_{load}"] = {
            name: {
                "fps": round(float(np.median([r["fps"] for r in rs if "fps" in r])), 2) if any("fps" in r for r in rs) else None,
                "cpu_s_per_frame": round(float(np.median([r["cpu_s"] for r in rs if "cpu_s" in r])), 3) if any("fps" in r for r in rs) else None,
                "layer_in_use": rs[0].get("layer"),
                "errors": [r["error"] for r in rs if "error" in r],
            }
            for name, rs in runs.items()
        }  # fmt: skip
    emit(record)


if __name__ == "__main__":
    main()
