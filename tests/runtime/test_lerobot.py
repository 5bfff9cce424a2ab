"""LeRobot datasets from rollouts: the v3.0 layout's invariants here, and LeRobot's own loader reading it.

The loader test runs ``lerobot`` 0.4.4 (PyPI) in its own environment (``make lerobot-env``, which
``.ci/run`` builds); without it the test is skipped with that reason.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from song.runtime.collect import CollectJob, _collect_job, depth_to_mm
from song.runtime.lerobot import TASK, V30, write_dataset

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = ROOT / "tests" / "artifacts" / "bench_golden"
LEROBOT_PYTHON = Path(
    os.environ.get("SONG_LEROBOT_PYTHON", ROOT / "build" / "bench-envs" / "lerobot" / "bin" / "python")
)
READER = ROOT / "tests" / "external" / "lerobot_read.py"
SENSORS = ("state", "depth", "rgb")


@pytest.fixture(scope="module")
def records() -> list[dict]:
    """Three real rollouts of the golden release (one succeeds), with depth and colour at 64×48."""
    from song.datasets.bench import open_benchmark

    bench = open_benchmark(str(GOLDEN))
    ids = [e.episode_id for e in bench.episodes(split="test")][:3]
    camera = {"width": 64, "height": 48}
    return [_collect_job(CollectJob(str(GOLDEN), i, "straight", SENSORS, camera, 10.0)) for i in ids]


def _write(out: Path, records: list[dict], version: str = "v3.0") -> Path:
    out.mkdir(parents=True)
    write_dataset(out, records, 10.0, "test", {"policy": "straight"}, version)
    return out


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_v30_layout_indexes_every_frame_once_and_is_deterministic(records, tmp_path: Path) -> None:
    import av
    import pandas as pd

    out = _write(tmp_path / "a", records)
    assert _tree(out) == _tree(_write(tmp_path / "b", records))  # same rollouts, same bytes
    info = json.loads((out / "meta" / "info.json").read_text())
    total = sum(r["steps"] for r in records)
    assert info["codebase_version"] == "v3.0" and info["total_frames"] == total and info["fps"] == 10
    assert info["features"]["observation.depth"] | {"info": None} == {
        "dtype": "uint16", "shape": [48, 64], "names": ["height", "width"], "info": None
    }  # fmt: skip
    episodes = pq.read_table(out / V30["episodes"].format(chunk_index=0, file_index=0)).to_pylist()
    assert [e["episode_index"] for e in episodes] == [0, 1, 2]
    assert [e["song_episode_id"] for e in episodes] == [r["episode_id"] for r in records]
    data = pq.read_table(out / V30["data"].format(chunk_index=0, file_index=0))
    assert data.num_rows == total and data.column("index").to_pylist() == list(range(total))
    key = "observation.images.rgb"
    start = 0
    for e, r in zip(episodes, records, strict=True):
        assert (e["dataset_from_index"], e["dataset_to_index"]) == (start, start + r["steps"])
        assert e[f"videos/{key}/from_timestamp"] == pytest.approx(start / 10.0)
        assert e[f"videos/{key}/to_timestamp"] == pytest.approx((start + r["steps"]) / 10.0)
        rows = data.slice(start, r["steps"])
        np.testing.assert_array_equal(np.array(rows.column("action").to_pylist(), np.float32), r["action"])
        np.testing.assert_array_equal(np.array(rows.column("observation.depth").to_pylist()), r["observation.depth"])
        assert e["stats/observation.depth/mean"] == pytest.approx([r["observation.depth"].mean()])
        assert np.array(e[f"stats/{key}/mean"]).shape == (3, 1, 1)
        start += r["steps"]
    video = out / V30["video"].format(video_key=key, chunk_index=0, file_index=0)
    with av.open(str(video)) as container:
        assert sum(1 for _ in container.decode(video=0)) == total  # one stream holds every episode
    tasks = pd.read_parquet(out / "meta" / "tasks.parquet")
    assert list(tasks.index) == [TASK] and tasks.loc[TASK, "task_index"] == 0
    stats = json.loads((out / "meta" / "stats.json").read_text())
    action = np.concatenate([r["action"] for r in records])
    np.testing.assert_allclose(stats["action"]["mean"], action.mean(axis=0), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(stats["action"]["std"], action.std(axis=0), rtol=1e-6, atol=1e-9)
    assert stats["action"]["count"] == [total]


def test_v21_stays_available_for_older_stacks(records, tmp_path: Path) -> None:
    out = _write(tmp_path / "v21", records, "v2.1")
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v2.1" and info["total_videos"] == 3
    lines = (out / "meta" / "episodes.jsonl").read_text().splitlines()
    assert [json.loads(line)["length"] for line in lines] == [r["steps"] for r in records]
    path = out / info["data_path"].format(episode_chunk=0, episode_index=2)
    assert pq.read_table(path).num_rows == records[2]["steps"]


def test_depth_is_stored_in_millimetres_with_zero_for_no_depth() -> None:
    depth = np.array([[0.0, 0.2804, 2.0], [np.inf, np.nan, 70.0]], np.float32)
    np.testing.assert_array_equal(depth_to_mm(depth), [[0, 280, 2000], [0, 0, 0]])


def _lerobot_ready() -> str | None:
    if not LEROBOT_PYTHON.exists():
        return f"no LeRobot environment at {LEROBOT_PYTHON} (make lerobot-env builds it; .ci/run does)"
    probe = subprocess.run([str(LEROBOT_PYTHON), "-c", "import lerobot.datasets.lerobot_dataset"], capture_output=True)
    return None if probe.returncode == 0 else f"lerobot does not import in {LEROBOT_PYTHON}"


@pytest.mark.parametrize("backend", ["pyav", "torchcodec"])
def test_lerobot_reads_the_dataset_back(records, tmp_path: Path, backend: str) -> None:
    """LeRobot 0.4.4's ``LeRobotDataset`` opens the folder, and every frame comes back as recorded."""
    reason = _lerobot_ready()
    if reason and "SONG_LEROBOT_PYTHON" in os.environ:  # make test-lerobot: the reader must be there
        pytest.fail(reason)
    if reason:
        pytest.skip(reason)
    out = _write(tmp_path / "ds", records)
    npz = tmp_path / "read.npz"
    env = os.environ | {"HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(tmp_path / "hf")}
    run = subprocess.run([str(LEROBOT_PYTHON), str(READER), str(out), str(npz), backend], capture_output=True,
                         text=True, env=env, timeout=600)  # fmt: skip
    if backend == "torchcodec" and "torchcodec" in run.stderr and "FFmpeg" in run.stderr:
        pytest.skip("torchcodec cannot load FFmpeg's libraries here (apt-get install ffmpeg); pyav read it")
    assert run.returncode == 0, run.stderr[-3000:]
    got = np.load(npz)
    about = json.loads(str(got["about"]))
    assert about["version"] == "v3.0" and about["episodes"] == 3 and about["tasks"] == [TASK] and about["fps"] == 10
    assert {"action", "observation.state", "observation.depth", "observation.images.rgb"} <= set(about["stats_keys"])
    np.testing.assert_array_equal(got["action"], np.concatenate([r["action"] for r in records]))
    np.testing.assert_array_equal(got["observation_state"], np.concatenate([r["observation.state"] for r in records]))
    np.testing.assert_array_equal(got["observation_depth"], np.concatenate([r["observation.depth"] for r in records]))
    assert got["episode_index"].tolist() == [i for i, r in enumerate(records) for _ in range(r["steps"])]
    assert got["frame_index"].tolist() == [t for r in records for t in range(r["steps"])]
    rendered = np.concatenate([r["observation.images.rgb"] for r in records]).astype(np.int16)  # (n, H, W, 3)
    decoded = got["rgb"].transpose(0, 2, 3, 1).astype(np.int16)  # LeRobot: (n, 3, H, W) in [0, 1]
    assert decoded.shape == rendered.shape
    error = np.abs(decoded - rendered).mean(axis=(1, 2, 3))
    assert error.max() < 4.0, error.max()  # H.264 at crf 20: each frame is the one recorded at its step
    shifted = np.abs(decoded[1:] - rendered[:-1]).mean(axis=(1, 2, 3))
    assert np.median(shifted) > np.median(error[1:])  # not a neighbour's frame
