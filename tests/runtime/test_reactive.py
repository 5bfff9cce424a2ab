"""Reactive pedestrians (an option): people near the robot avoid it, rejoin their tracks; replay is untouched."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from song.cli import app
from song.config import RobotConfig
from song.datasets.bench.types import pedestrian_states, track_motion
from song.runtime.avatars import make_collider
from song.runtime.loop import EpisodeRunner, reactive_setup
from song.runtime.reactive import orca_line, solve_one
from tests.runtime.helpers import episode, track

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"


def _crossing():
    # the robot stands still in the middle of the room; one pedestrian walks straight through where it stands,
    # another crosses diagonally close to it
    peds = [track(0, (1.0, 3.02), (9.0, 3.02), speed=1.0), track(1, (9.0, 2.0), (1.0, 4.0), speed=1.2)]
    return episode(start=(5.0, 3.0), goal=(9.5, 5.5), peds=peds, robot=RobotConfig(max_steps=120))


def _stand(runner: EpisodeRunner, seen: list | None = None):
    """Step a robot that stands still to the end; ``seen`` collects the pedestrians' positions at each step."""
    while runner.outcome is None:
        runner.step(0.0, 0.0)
        if seen is not None:
            seen.append(pedestrian_states(runner.episode.pedestrians, runner.time)[1])
    return runner.result()


def test_reactive_pedestrians_walk_around_a_robot_on_their_path_and_rejoin_their_tracks() -> None:
    ep = _crossing()
    before = [t.xy.copy() for t in ep.pedestrians]
    replay = _stand(EpisodeRunner(ep, make_collider(ep)))
    assert replay.outcome == "human" and replay.nearest.min() < 0.3  # the recording walks into it
    reactive, collider, crowd = reactive_setup(ep)
    seen: list[np.ndarray] = []
    result = _stand(EpisodeRunner(reactive, collider, None, crowd), seen)
    contact = ep.params.pedestrian_radius_m + ep.params.robot.radius_m
    assert result.outcome == "timeout" and result.max_gaussian_count == 0
    assert result.nearest.min() >= contact  # everyone kept clear of it
    assert np.abs(crowd.offset).max() < 0.05  # and walked back onto its recorded way afterwards
    ped_xy = np.array(seen)  # as everyone saw them at each step (later steps rewrite the tracks' future)
    pairs = np.linalg.norm(ped_xy[:, 0] - ped_xy[:, 1], axis=-1)
    assert pairs.min() >= 2 * ep.params.pedestrian_radius_m - 0.01  # not into each other either
    steps = np.linalg.norm(np.diff(ped_xy, axis=0), axis=-1) * reactive.params.robot.control_hz
    assert steps.max() <= 1.3 * 1.2 + 0.05  # no jumps: within the walkers' speed limit
    assert all(np.array_equal(t.xy, b) for t, b in zip(ep.pedestrians, before, strict=True))  # a copy was moved
    assert all(t.shift is None for t in ep.pedestrians)


def test_the_avatar_is_posed_where_the_pedestrian_is_with_its_gait_following_its_progress() -> None:
    ep = _crossing()
    reactive, collider, crowd = reactive_setup(ep)
    runner = EpisodeRunner(reactive, collider, None, crowd)
    recorded = make_collider(ep)
    shown_at, held = [], 0
    for _ in range(60):
        runner.step(0.0, 0.0)
        t = runner.time
        for k in range(2):
            shown, shift = track_motion(reactive.pedestrians[k], t)
            root = pedestrian_states(reactive.pedestrians[k : k + 1], t)[1][0]
            # the body is the recorded pose of time `shown`, moved to where the pedestrian is now
            body = collider.pose(k, t).mean(axis=0)[:2]
            assert np.allclose(body - recorded.pose(k, shown).mean(axis=0)[:2], shift, atol=1e-5)
            assert np.allclose(root - pedestrian_states(ep.pedestrians[k : k + 1], shown)[1][0], shift, atol=1e-9)
        shown_at.append(track_motion(reactive.pedestrians[0], runner.time)[0])
        held += int(abs(shown_at[-1] - runner.time) > 0.05)
    steps = np.diff(shown_at)
    assert (steps >= -1e-9).all() and steps.max() <= 2.0 / ep.params.robot.control_hz + 1e-9  # never backwards
    assert held > 0  # while it stepped round the robot its gait fell behind the recording's
    _stand(runner)
    for walker in reactive.pedestrians:  # back on their recordings: the recorded motion of now (its last, past it)
        shown, shift = track_motion(walker, runner.time)
        assert shown == pytest.approx(min(runner.time, walker.t[-1]), abs=0.05) and np.abs(shift).max() < 0.01


def test_replay_reads_the_release_as_it_is() -> None:
    ep = _crossing()
    runner = EpisodeRunner(ep, make_collider(ep))
    assert runner.crowd is None and runner.episode.pedestrians is ep.pedestrians
    first = _stand(runner)
    second = _stand(EpisodeRunner(ep, make_collider(ep)))
    assert np.array_equal(first.trajectory, second.trajectory) and np.array_equal(first.nearest, second.nearest)


def test_the_orca_velocity_keeps_clear_of_the_robot_over_the_horizon() -> None:
    rng = np.random.default_rng(3)
    radius, tau = 0.5, 3.0
    checked = 0
    for _ in range(400):
        p, robot = rng.uniform(-3, 3, 2), rng.uniform(-3, 3, 2)
        if np.hypot(*(p - robot)) <= radius + 0.05:
            continue
        v, robot_v, preferred = rng.uniform(-1, 1, (3, 2))
        point, direction = orca_line(p, v, robot, robot_v, radius, tau, 0.1)
        x = solve_one(point, direction, preferred, 1.5)
        assert np.hypot(*x) <= 1.5 + 1e-9
        if direction[0] * (point[1] - x[1]) - direction[1] * (point[0] - x[0]) > 1e-9:
            continue  # the line misses the speed circle: no velocity within the limit avoids it
        s = np.linspace(0.0, tau, 200)[:, None]
        gap = np.hypot(*((p + s * x) - (robot + s * robot_v)).T)
        assert gap.min() >= radius - 1e-6
        checked += 1
    assert checked > 300


def test_eval_records_reactive_pedestrians_as_an_unofficial_mode(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    base = ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--out", str(out)]
    assert CliRunner().invoke(app, base).exit_code == 0
    result = CliRunner().invoke(app, [*base, "--set", "crowd.react_to_robot=true"])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "straight-reactive.json").read_text())
    assert summary["pedestrians"] == "reactive" and summary["official"] is False and not summary["overrides"]
    assert json.loads((out / "straight.json").read_text())["pedestrians"] == "replay"
    rows = pq.read_table(out / "straight-reactive.parquet").column("policy").to_pylist()
    assert set(rows) == {"straight (reactive pedestrians)"}
    table = (out / "results.md").read_text()
    assert table.index("| straight | all |") < table.index("| straight (reactive pedestrians) | all |")
    bad = CliRunner().invoke(app, [*base, "--set", "crowd.react_to_robot=maybe"])
    assert bad.exit_code != 0 and "crowd.react_to_robot" in bad.output


def test_the_gymnasium_env_steps_reactive_pedestrians() -> None:
    from song.runtime.env import SongNavEnv

    env = SongNavEnv(str(GOLDEN), sensors=("state",), reactive=True)
    _, info = env.reset(seed=0)
    assert env.runner.crowd is not None and env.runner.episode.pedestrians[0].shift is not None
    for _ in range(5):
        env.step(np.array([0.3, 0.0], dtype=np.float32))
    replay = SongNavEnv(str(GOLDEN), sensors=("state",))
    replay.reset(seed=0)
    assert replay.runner.crowd is None and replay.runner.episode.pedestrians[0].shift is None


def test_collect_records_reactive_pedestrians(tmp_path: Path) -> None:
    from song.runtime.collect import collect

    summary = collect(str(GOLDEN), "straight", tmp_path / "ds", split="test", limit=1, keep="all", reactive=True)
    info = json.loads((Path(summary.out) / "meta" / "info.json").read_text())
    assert info["song"]["pedestrians"] == "reactive"
    plain = collect(str(GOLDEN), "straight", tmp_path / "plain", split="test", limit=1, keep="all")
    assert json.loads((Path(plain.out) / "meta" / "info.json").read_text())["song"]["pedestrians"] == "replay"


def test_a_recording_closer_to_a_wall_than_a_body_is_still_walked() -> None:
    # the golden release's pedestrian 0 walks 0.2 m from a wall (its body is 0.25 m) away from the robot's
    # start: its own recorded step is the replay's, taken even though no step there is free
    from song.datasets.bench import open_benchmark

    recorded = open_benchmark(GOLDEN).episode("scene_1-001")
    ep, collider, crowd = reactive_setup(recorded, True)
    ped = recorded.pedestrians[0]
    assert crowd.world.collides(pedestrian_states([ped], 0.6)[1][0], crowd.body)[()]  # the recording itself
    robot, t = np.array(recorded.start_xy, float), recorded.t0
    for _ in range(5):  # the robot follows it at 0.5 m/s
        robot = robot + np.array([0.05, 0.0])
        crowd.advance(t, t + 0.1, robot, np.array([0.5, 0.0]))
        t += 0.1
        np.testing.assert_allclose(pedestrian_states(ep.pedestrians[:1], t)[1], pedestrian_states([ped], t)[1])
        assert collider.count(t, robot) == 0  # it is not held back into the robot's way
