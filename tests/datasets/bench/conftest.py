"""A synthetic graded run (scenes, crowd.parquet, grading manifest) for release tests.

It follows the stage contracts (crowd.parquet columns, RUN/manifest/episodes.parquet) without running
the stages, so the release format is tested on its own.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from song.config import SongConfig
from song.datasets.run import RunFolder
from song.datasets.run.integrity import graded_inputs, stage_settings
from song.datasets.scenes import load_scene_package
from song.pipeline.chain import iter_run
from song.util import sha256_file, write_json_atomic
from tests.conftest import build_two_room_scene

DIFFICULTY = ["hard", "medium", "medium", "easy", "easy"]


def _crowd(path: Path, n_peds: int) -> None:
    rows = {"ped_id": [], "frame": [], "t": [], "x": [], "y": [], "yaw": [], "speed": []}
    for ped in range(n_peds):
        for frame in range(ped * 5, ped * 5 + 90):
            t = frame / 30
            rows["ped_id"].append(ped)
            rows["frame"].append(frame)
            rows["t"].append(t)
            rows["x"].append(0.5 + 0.8 * (t - ped * 5 / 30))
            rows["y"].append(1.0 + 0.6 * ped)
            rows["yaw"].append(0.0)
            rows["speed"].append(0.8)
    schema = pa.schema(
        [("ped_id", pa.int32()), ("frame", pa.int32()), ("t", pa.float64()), ("x", pa.float64())]
        + [("y", pa.float64()), ("yaw", pa.float64()), ("speed", pa.float64())]
    )
    pq.write_table(pa.table(rows, schema=schema), path)


def build_graded_run(root: Path, n_scenes: int = 2, episodes_per_scene: int = 5, shift: float = 0.0) -> Path:
    scenes = root / "scenes"
    for k in range(n_scenes):
        build_two_room_scene(scenes, f"scene_{k}")
    run = root / "run"
    list(iter_run(scenes, run, SongConfig(), stage_names=[]))
    rows = []
    for k in range(n_scenes):
        _crowd(run / "scenes" / f"scene_{k}" / "crowd.parquet", 2 + k)
        # what a completed crowd stage records: its outputs and the scene files it read
        files = load_scene_package(scenes / f"scene_{k}").content_hash()
        outputs = {"crowd.parquet": sha256_file(run / "scenes" / f"scene_{k}" / "crowd.parquet")}
        made_from = {"scene": files, "settings": stage_settings(SongConfig(), ()), "depends": {}}
        record = {"crowd": {"status": "ok", "input_hash": "synthetic", "outputs": outputs, **made_from}}
        write_json_atomic(run / "scenes" / f"scene_{k}" / "stages.json", record)
        for e in range(episodes_per_scene):
            length = 3.0 + e + shift
            rows.append(
                {
                    "episode_id": f"scene_{k}-{e:03d}",
                    "scene_id": f"scene_{k}",
                    "mode": ["co_directional", "counter_directional", "encounter", "random"][e % 4],
                    "seed": 1000 * k + e,
                    "t0": 0.5 * e,
                    "start_x": 0.6,
                    "start_y": 1.0 + 0.1 * e,
                    "start_yaw": 0.3 * e,
                    "goal_x": 6.5,
                    "goal_y": 2.0,
                    "path": [[0.6, 1.0 + 0.1 * e], [4.0, 2.0], [6.5, 2.0]],
                    "geodesic_distance": length,
                    "optimal_time": length / 0.5,
                    "path_length": length,
                    "n_turns": e % 3,
                    "n_encounters": e,
                    "corridor_width": 1.5 - 0.1 * e,
                    "bin_length": e % 3,
                    "bin_turns": e % 3,
                    "bin_encounters": e % 3,
                    "bin_width": e % 3,
                    "score": 4 * (e % 3),
                    "difficulty": DIFFICULTY[e % 5],
                    "pedestrian_ids": list(range(2 + k)),
                    "reference_ped": -1 if e % 4 == 3 else 0,
                    "encounter_time": None if e % 4 == 3 else 0.5 * e + 2.0,
                }
            )
    (run / "manifest").mkdir()
    pq.write_table(pa.Table.from_pylist(rows), run / "manifest" / "episodes.parquet")
    inputs = {f"scene_{k}": graded_inputs(RunFolder(run).scene(f"scene_{k}")) for k in range(n_scenes)}
    write_json_atomic(run / "manifest" / "summary.json", {"inputs": inputs})  # what a grade records of its inputs
    return run


@pytest.fixture
def graded_run(tmp_path: Path) -> Callable[..., Path]:
    def factory(name: str = "a", **kw) -> Path:
        return build_graded_run(tmp_path / name, **kw)

    return factory


@pytest.fixture
def np_rng() -> np.random.Generator:
    return np.random.default_rng(0)
