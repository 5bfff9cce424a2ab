"""Batched cameras: N envs in one process, cameras rendered together against N separate renders, interleaved.

    .venv/bin/python benchmarks/batched_cameras.py --bench runs/demo-bench [--envs 1 4 16] [--steps 12] [--rounds 2]

For each camera size (160×120, 320×240) and env count N: env-steps per second of wall time with sensors
``state`` + ``rgbd`` and a fixed command (episodes restart as they end), for
- ``together``: :class:`song.runtime.env.SongVectorEnv` (one ``render_views`` call per step for all N
  cameras: one projection buffer, one binning, one parallel compositing loop over every camera's tiles);
- ``separate``: the same N envs stepped one after another, each rendering its own camera (what a
  ``SyncVectorEnv`` of copies does).
Both see the same episodes (env i seeded with i). Also the numba threading layer and the load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.runtime.env import SongNavEnv, SongVectorEnv  # noqa: E402

SIZES = [(160, 120), (320, 240)]
COMMAND = np.array([0.3, 0.1], np.float32)


def _together(bench: str, n: int, size: tuple[int, int], steps: int) -> float:
    vector = SongVectorEnv(bench, n, sensors=("state", "rgbd"), resolution=size)
    vector.reset(seed=0)
    actions = np.tile(COMMAND, (n, 1))
    vector.step(actions)  # scenes loaded, kernels compiled
    start = time.perf_counter()
    for _ in range(steps):
        vector.step(actions)
    return n * steps / (time.perf_counter() - start)


def _separate(bench: str, n: int, size: tuple[int, int], steps: int) -> float:
    envs = [SongNavEnv(bench, sensors=("state", "rgbd"), resolution=size) for _ in range(n)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
        env.step(COMMAND)
    start = time.perf_counter()
    for _ in range(steps):
        for env in envs:
            _, _, terminated, truncated, _ = env.step(COMMAND)
            if terminated or truncated:
                env.reset()
    return n * steps / (time.perf_counter() - start)


def main() -> None:
    import numba

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", required=True)
    parser.add_argument("--envs", type=int, nargs="+", default=[1, 4, 16])
    parser.add_argument("--steps", type=int, default=12)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    record: dict = {"cpu_count": os.cpu_count(), "numba_threads": numba.get_num_threads(),
                    "load_1min_start": round(os.getloadavg()[0], 2), "sizes": {}}  # fmt: skip
    for width, height in SIZES:
        rows = {}
        for n in args.envs:
            together, separate = [], []
            for _ in range(args.rounds):  # interleaved: the machine is shared
                together.append(round(_together(args.bench, n, (width, height), args.steps), 2))
                separate.append(round(_separate(args.bench, n, (width, height), args.steps), 2))
            rows[str(n)] = {"together_env_steps_per_s": together, "separate_env_steps_per_s": separate,
                            "ratio_median": round(float(np.median(together) / np.median(separate)), 3)}  # fmt: skip
        record["sizes"][f"{width}x{height}"] = rows
    record["threading_layer"] = numba.threading_layer()
    record["load_1min_end"] = round(os.getloadavg()[0], 2)
    emit(record)


if __name__ == "__main__":
    main()
