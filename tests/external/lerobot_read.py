"""Read a SONG dataset with LeRobot's own ``LeRobotDataset`` (run in the environment that has ``lerobot``).

Usage: ``python lerobot_read.py DATASET OUT.npz BACKEND`` (BACKEND: ``pyav`` or ``torchcodec``). Writes
every frame's features as LeRobot returns them, so the test in the SONG environment can compare them
with what was recorded. Not imported by SONG or its tests: it runs in its own interpreter.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def main(root: str, out: str, backend: str) -> None:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("song/local", root=root, video_backend=backend)
    keys = ("action", "observation.state", "observation.depth", "episode_index", "frame_index", "index")
    columns: dict[str, list] = {key: [] for key in (*keys, "rgb")}
    tasks = set()
    for i in range(len(dataset)):
        item = dataset[i]
        for key in keys:
            columns[key].append(item[key].numpy())
        columns["rgb"].append(np.rint(item["observation.images.rgb"].numpy() * 255).astype(np.uint8))
        tasks.add(item["task"])
    arrays = {key.replace(".", "_"): np.stack(values) for key, values in columns.items()}
    about = {
        "version": dataset.meta.info["codebase_version"],
        "episodes": dataset.meta.total_episodes,
        "fps": dataset.fps,
        "tasks": sorted(tasks),
        "stats_keys": sorted(dataset.meta.stats),
        "backend": backend,
    }
    np.savez(out, about=json.dumps(about), **arrays)


if __name__ == "__main__":
    main(*sys.argv[1:4])
