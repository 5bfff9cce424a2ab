"""Gymnasium contract and ``song eval`` on the golden tiny release."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from song.cli import app
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
    np.testing.assert_array_equal(a["state"]["goal"], b["state"]["goal"])


@pytest.mark.parametrize(
    "sensors", [("state",), ("scan",), ("pedestrians",), ("map",), ("state", "scan", "pedestrians", "map")]
)
def test_every_sensor_matches_its_declared_space(sensors: tuple[str, ...]) -> None:
    pytest.importorskip("gymnasium")
    from gymnasium.utils.env_checker import check_env

    from song.runtime.env import SongNavEnv
    from song.runtime.sensors import space_contains

    env = SongNavEnv(str(GOLDEN), sensors=sensors)
    check_env(env, skip_render_check=True)
    declared = env.sensors.space()
    for episode_id in env.episode_ids:
        obs, _ = env.reset(options={"episode_id": episode_id})
        done = False
        while not done:
            assert set(obs) == set(sensors) and space_contains(declared, obs)
            assert env.observation_space.contains(obs)
            obs, _, terminated, truncated, _ = env.step(np.array([0.5, 0.3], dtype=np.float32))
            done = terminated or truncated


def test_the_map_sensor_is_the_static_map_around_the_robot() -> None:
    from song.datasets.bench import open_benchmark
    from song.runtime.loop import EpisodeRunner
    from song.runtime.sensors import SensorSuite

    bench = open_benchmark(GOLDEN)
    episode = next(iter(bench.episodes()))
    suite = SensorSuite.build(["map"], episode.params, options={"map": {"size": 9}})
    runner = EpisodeRunner(episode, None, suite)
    crop = runner.observation()["map"]
    grid = episode.static_map
    rows = grid.cells.shape[0]
    col = int((runner.pose.x - grid.origin[0]) // grid.resolution)
    row = rows - 1 - int((runner.pose.y - grid.origin[1]) // grid.resolution)
    np.testing.assert_array_equal(crop, grid.cells[row - 4 : row + 5, col - 4 : col + 5])
    assert crop[4, 4] == 255  # the robot starts on a free cell


def test_policies_and_env_read_the_release_parameters(tmp_path: Path) -> None:
    """A release recording another robot and body radius changes what the runtime uses (no hard-coded copies)."""
    import json
    import shutil

    from song.runtime.env import SongNavEnv

    copy = tmp_path / "1.0.0"
    shutil.copytree(GOLDEN / "1.0.0", copy)
    info = json.loads((copy / "meta/info.json").read_text())
    info["robot"]["max_speed_mps"] = 0.3
    info["pedestrian_radius_m"] = 0.4
    import pyarrow.parquet as pq

    from song.datasets.bench.info import fingerprint_of

    info["fingerprint"] = fingerprint_of(pq.read_table(copy / "meta/manifest.parquet").to_pylist(), info)
    (copy / "meta/info.json").write_text(json.dumps(info))  # a release that records other parameters
    bench = open_benchmark(copy)
    assert bench.params.robot.max_speed_mps == 0.3 and bench.params.pedestrian_radius_m == 0.4
    env = SongNavEnv(str(copy))
    assert env.action_space.high[0] == pytest.approx(0.3)
    result = next(iter_eval(bench, "straight"))
    steps = np.linalg.norm(np.diff(result.trajectory[:, :2], axis=0), axis=1)
    assert steps.max() <= 0.3 * 0.1 + 1e-9


def test_eval_override_needs_the_flag_and_is_recorded(tmp_path: Path) -> None:
    config = tmp_path / "faster.toml"
    config.write_text("[robot]\nmax_speed_mps = 0.8\n")
    out = tmp_path / "eval"
    args = ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--out", str(out), "-c", str(config)]
    refused = CliRunner().invoke(app, args)
    assert refused.exit_code == 2 and "--override" in refused.output and not out.exists()
    same = tmp_path / "same.toml"
    same.write_text("[robot]\nmax_speed_mps = 0.5\n")  # the release's own value is no override
    assert CliRunner().invoke(app, [*args[:-1], str(same)]).exit_code == 0
    accepted = CliRunner().invoke(app, [*args, "--override"])
    assert accepted.exit_code == 0, accepted.output
    assert "override robot.max_speed_mps: 0.5 → 0.8" in accepted.output
    summary = json.loads((out / "straight.json").read_text())
    bench = open_benchmark(GOLDEN)
    assert summary["official"] is False
    assert summary["overrides"] == {"robot.max_speed_mps": [0.5, 0.8]}
    assert summary["release"]["fingerprint"] == bench.info.fingerprint
    assert summary["params"]["robot"]["max_speed_mps"] == 0.8 and summary["sensors"][0]["name"] == "state"
    meta = json.loads(pq.read_schema(out / "straight.parquet").metadata[b"song.eval"])
    assert meta["overrides"] == summary["overrides"] and meta["release"]["version"] == bench.version


def test_eval_outcomes_and_cli(tmp_path: Path) -> None:
    bench = open_benchmark(GOLDEN)
    results = list(iter_eval(bench, "astar"))
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
    assert summary["official"] is True and summary["release"]["fingerprint"] == bench.info.fingerprint
    assert "| astar | all |" in (out / "results.md").read_text()
    again = tmp_path / "again"
    CliRunner().invoke(app, ["eval", "--bench", str(GOLDEN), "--policy", "astar", "--out", str(again), "-j", "2"])
    assert (again / "astar.parquet").read_bytes() == (out / "astar.parquet").read_bytes()


def test_render_mode_camera_size_and_the_step_limit_through_gym_make() -> None:
    gym = pytest.importorskip("gymnasium")
    from gymnasium.utils.env_checker import check_env

    from song.runtime.env import ENV_ID, make

    env = gym.make(f"song.runtime.env:{ENV_ID}", bench=str(GOLDEN), sensors=("state", "rgb"), resolution=(40, 30),
                   render_mode="rgb_array", render_backend="numba")  # fmt: skip
    check_env(env.unwrapped)  # the render check included
    obs, _ = env.reset(seed=0)
    assert obs["rgb"].shape == (30, 40, 3)
    picture = env.render()
    assert picture.dtype == np.uint8 and picture.ndim == 3 and picture.shape[1] > 2 * picture.shape[0]  # RGB|depth|map
    limited = make(str(GOLDEN), sensors=("state",))
    assert limited.spec.max_episode_steps == open_benchmark(GOLDEN).params.robot.max_steps
    from song.runtime.env import SongNavEnv

    with pytest.raises(ValueError, match="render_mode"):
        SongNavEnv(str(GOLDEN), render_mode="ansi")


def test_a_vector_env_of_spawned_copies() -> None:
    pytest.importorskip("gymnasium")
    from song.runtime.env import make_vector

    vector = make_vector(str(GOLDEN), 2, sensors=("state", "scan"))
    try:
        obs, info = vector.reset(seed=[1, 2])
        assert obs["scan"].shape == (2, 72) and len(info["episode_id"]) == 2
        assert vector.single_observation_space["scan"].shape == (72,)
        for _ in range(5):
            obs, reward, terminated, truncated, info = vector.step(np.tile([0.3, 0.0], (2, 1)).astype(np.float32))
        assert reward.shape == (2,) and obs["state"]["pose"].shape == (2, 3)
    finally:
        vector.close()


def test_the_batched_vector_env_equals_its_envs_stepped_alone() -> None:
    """Cameras rendered together give each env the observation it gets alone, through episode ends."""
    pytest.importorskip("gymnasium")
    from song.runtime.env import SongNavEnv, SongVectorEnv

    kwargs = {"sensors": ("state", "rgbd"), "resolution": (40, 30)}
    vector = SongVectorEnv(str(GOLDEN), 3, **kwargs)
    alone = [SongNavEnv(str(GOLDEN), **kwargs) for _ in range(3)]
    assert vector.observation_space["rgbd"]["rgb"].shape == (3, 30, 40, 3)
    obs, info = vector.reset(seed=7)
    singles = [env.reset(seed=7 + i) for i, env in enumerate(alone)]
    assert list(info["episode_id"]) == [i["episode_id"] for _, i in singles]
    rng = np.random.default_rng(0)
    ended, resets = [False] * 3, 0
    for _ in range(60):
        actions = np.column_stack([rng.uniform(0.2, 1.0, 3), rng.uniform(-0.5, 0.5, 3)]).astype(np.float32)
        obs, reward, terminated, truncated, _ = vector.step(actions)
        for i, env in enumerate(alone):
            if ended[i]:  # next-step autoreset: the env starts its next episode, reward 0
                o, r = env.reset()[0], 0.0
                resets += 1
                ended[i] = False
            else:
                o, r, term, trunc, _ = env.step(actions[i])
                ended[i] = term or trunc
                assert (terminated[i], truncated[i]) == (term, trunc)
            assert reward[i] == r
            assert obs["rgbd"]["rgb"][i].tobytes() == o["rgbd"]["rgb"].tobytes()
            assert obs["rgbd"]["depth"][i].tobytes() == o["rgbd"]["depth"].tobytes()
            np.testing.assert_array_equal(obs["state"]["pose"][i], o["state"]["pose"])
    assert resets >= 1  # the episodes ended (speed 0.2–1 m/s, random turns) and the envs went on


def test_the_batched_vector_env_works_with_gymnasiums_vector_wrappers() -> None:
    """Gymnasium's own vector wrappers take it: episode statistics at episode ends, and rendering."""
    pytest.importorskip("gymnasium")
    from gymnasium.wrappers.vector import RecordEpisodeStatistics

    from song.runtime.env import SongVectorEnv

    vector = RecordEpisodeStatistics(SongVectorEnv(str(GOLDEN), 2, sensors=("state",), render_mode="rgb_array"))
    vector.reset(seed=1)
    ended = 0
    for _ in range(400):
        _, _, terminated, truncated, info = vector.step(np.tile([1.0, 0.0], (2, 1)).astype(np.float32))
        if (terminated | truncated).any():
            ended += 1
            assert "episode" in info and info["episode"]["l"][info["_episode"]].min() >= 1
            break
    assert ended
    frames = vector.render()
    assert len(frames) == 2 and all(f.dtype == np.uint8 and f.ndim == 3 for f in frames)
    vector.close()
