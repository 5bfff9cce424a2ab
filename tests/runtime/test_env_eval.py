"""Gymnasium contract and ``song eval`` on the golden tiny release."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from song.cli import app
from song.config import RobotConfig
from song.datasets.bench import open_benchmark
from song.runtime.evaluate import iter_eval, summarize

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"


def test_check_env_and_contract() -> None:
    gym = pytest.importorskip("gymnasium")
    from gymnasium.utils.env_checker import check_env

    from song.runtime.env import ENV_ID, SongNavEnv, register

    env = SongNavEnv(str(GOLDEN))
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=3, options={"episode_id": "scene_1-002"})
    assert info["episode_id"] == "scene_1-002" and obs["scan"].shape == (72,)
    done = False
    steps = 0
    while not done:
        obs, reward, terminated, truncated, info = env.step(np.array([0.5, 0.0], dtype=np.float32))
        assert not (terminated and truncated)
        done = terminated or truncated
        steps += 1
    assert steps <= 200 and info["outcome"] in ("success", "obstacle", "human", "timeout")
    register()
    assert ENV_ID == "song/SongNav-v1" and ENV_ID in gym.registry
    a, _ = env.reset(seed=11)
    b, _ = env.reset(seed=11)
    np.testing.assert_array_equal(a["goal"], b["goal"])


def test_eval_outcomes_and_cli(tmp_path: Path) -> None:
    bench = open_benchmark(GOLDEN)
    results = list(iter_eval(bench, "astar", RobotConfig()))
    assert len(results) == len(bench)
    row = summarize(results)["all"]
    assert row["SR"] + row["CR_obs"] + row["CR_hum"] + row["TO"] == pytest.approx(100.0)
    out = tmp_path / "eval"
    result = CliRunner().invoke(
        app, ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--policy", "astar", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    table = pq.read_table(out / "astar.parquet")
    assert table.num_rows == len(bench) and table.column("episode_id").to_pylist() == sorted(bench.episode_ids())
    summary = json.loads((out / "astar.json").read_text())
    assert summary["metrics"]["all"]["n"] == len(bench)
    assert "| astar | all |" in (out / "results.md").read_text()
    again = tmp_path / "again"
    CliRunner().invoke(app, ["eval", "--bench", str(GOLDEN), "--policy", "astar", "--out", str(again), "-j", "2"])
    assert (again / "astar.parquet").read_bytes() == (out / "astar.parquet").read_bytes()
