"""Gymnasium env throughput: one env in-process against a vector env of N copies, interleaved.

    .venv/bin/python benchmarks/gym_env.py --bench runs/demo-bench [--envs 2] [--steps 60] [--rounds 2]

For each sensor set (``state`` only; ``state`` + ``depth`` at 160×120), env-steps per second of wall
time over ``--steps`` steps with a fixed command, episodes reset as they end: ``song.runtime.env.make``
(one process) and ``make_vector`` (``AsyncVectorEnv``, spawned workers, the cores shared among them).
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

from song.runtime.env import make, make_vector  # noqa: E402

SETS = {"state": {"sensors": ("state",)}, "depth_160x120": {"sensors": ("state", "depth"), "resolution": (160, 120)}}


def _single(bench: str, steps: int, kwargs: dict) -> float:
    env = make(bench, **kwargs)
    env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(np.array([0.3, 0.1], np.float32))
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def _vector(bench: str, envs: int, steps: int, kwargs: dict) -> float:
    vector = make_vector(bench, envs, **kwargs)
    vector.reset(seed=0)
    vector.step(np.tile([0.3, 0.1], (envs, 1)).astype(np.float32))  # workers warm (numba caches loaded)
    start = time.perf_counter()
    for _ in range(steps):
        vector.step(np.tile([0.3, 0.1], (envs, 1)).astype(np.float32))
    rate = envs * steps / (time.perf_counter() - start)
    vector.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bench", required=True)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    record: dict = {"cpu_count": os.cpu_count(), "envs": args.envs, "load_1min": round(os.getloadavg()[0], 2)}
    for name, kwargs in SETS.items():
        single, vector = [], []
        for _ in range(args.rounds):  # interleaved: the machine is shared
            single.append(round(_single(args.bench, args.steps, kwargs), 1))
            vector.append(round(_vector(args.bench, args.envs, args.steps, kwargs), 1))
        record[name] = {"single_env_steps_per_s": single, f"vector_{args.envs}_env_steps_per_s": vector}
    emit(record)


if __name__ == "__main__":
    main()
