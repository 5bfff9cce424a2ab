"""Do episodes contain the interaction their mode promises? Walking pedestrians near the robot's path.

    .venv/bin/python benchmarks/episodes.py --run RUN [--episodes 500] [--generated 0]

Grades a copy of RUN (a synth run with the crowd stage; with ``--generated N`` the script makes one
itself from the sample scenes plus N generated scenes) and reports, per mode and per difficulty, the
share of episodes in which some pedestrian *walking* (> 0.2 m/s) comes within 3 m of the robot's A*
path while the robot traverses it at its nominal speed (frames t0 … t0 + T*). Prints JSON.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import SongConfig  # noqa: E402
from song.datasets.run import read_crowd  # noqa: E402
from song.pipeline.chain import iter_run  # noqa: E402
from song.pipeline.grading import grade_run  # noqa: E402

NEAR_M, WALKING_MPS = 3.0, 0.2


def _segment_distance(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """(N,) distance from each point to the polyline ``path``."""
    a, b = path[:-1], path[1:]
    ab = b - a
    s = np.clip(((points[:, None] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + s[..., None] * ab), axis=-1).min(axis=1)


def has_walker_near_path(row: dict, xy: np.ndarray, fps: int) -> bool:
    """Some pedestrian walks within ``NEAR_M`` of the path during the robot's nominal traversal."""
    f0 = int(round(row["t0"] * fps))
    f1 = min(int(round((row["t0"] + row["optimal_time"]) * fps)), xy.shape[1] - 1)
    if f1 <= f0:
        return False
    seg = xy[:, max(f0 - 1, 0) : f1 + 1]
    speed = np.linalg.norm(np.diff(seg, axis=1), axis=-1) * fps
    pts = seg[:, 1:]
    near = _segment_distance(pts.reshape(-1, 2), np.asarray(row["path"])).reshape(speed.shape) <= NEAR_M
    return bool((near & (speed > WALKING_MPS)).any())


def measure(run: Path, episodes: int) -> dict:
    work = Path(tempfile.mkdtemp(prefix="song-episodes-"))
    try:
        graded = work / "run"
        shutil.copytree(run, graded, ignore=shutil.ignore_patterns("manifest"))
        grade_run(graded, n_episodes=episodes, workers=2)
        rows = pq.read_table(graded / "manifest" / "episodes.parquet").to_pylist()
        crowds = {}
        hit = []
        for row in rows:
            if row["scene_id"] not in crowds:
                crowds[row["scene_id"]] = read_crowd(graded / "scenes" / row["scene_id"])
            crowd = crowds[row["scene_id"]]
            hit.append(has_walker_near_path(row, crowd.xy, crowd.fps))
    finally:
        shutil.rmtree(work, ignore_errors=True)

    def share(key: str) -> dict:
        out = {}
        for value in sorted({r[key] for r in rows}):
            sel = [h for h, r in zip(hit, rows, strict=True) if r[key] == value]
            out[value] = {"episodes": len(sel), "walking_within_3m": round(float(np.mean(sel)), 4)}
        return out

    return {"episodes": len(rows), "walking_within_3m": round(float(np.mean(hit)), 4), "by_mode": share("mode"),
            "by_difficulty": share("difficulty")}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--run", type=Path, help="a synth run with crowds (default: made from the samples)")
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--generated", type=int, default=0, help="generated scenes added to the samples")
    args = parser.parse_args()
    if args.run is not None:
        emit(measure(args.run, args.episodes))
        return
    work = Path(tempfile.mkdtemp(prefix="song-episodes-run-"))
    try:
        scenes = work / "scenes"
        shutil.copytree(ROOT / "datasets" / "sample_scenes", scenes, ignore=shutil.ignore_patterns("*.md", "*.txt"))
        if args.generated:
            from song.datasets.scenes.generate import VENUE_ORDER, generate_scene

            for k in range(args.generated):
                venue = VENUE_ORDER[k % len(VENUE_ORDER)]
                generate_scene(f"gen_{venue}_{k:04d}", venue, 77, scenes, splat=False)
        list(iter_run(scenes, work / "run", SongConfig(seed=1), ["intents", "crowd"], workers=2))
        emit(measure(work / "run", args.episodes))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
