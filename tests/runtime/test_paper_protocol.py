"""The paper's evaluation protocol: waypoint policies and their tracker, image goals, the avatar-free ablation."""

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
from song.errors import SongError
from song.runtime.avatars import AvatarCollider, make_collider, proxy_poser
from song.runtime.loop import EpisodeRunner, run_episode
from song.runtime.policies import load_policy
from song.runtime.sensors import SensorSuite, goal_pose
from song.runtime.waypoints import PurePursuitTracker
from tests.runtime.helpers import episode

GOLDEN = Path(__file__).resolve().parents[1] / "artifacts" / "bench_golden"


class Arc:
    """A waypoint policy: a left-curving arc ahead at 2 Hz, then straight at the goal."""

    sensors = ("state",)
    rate_hz = 2.0

    def reset(self, episode) -> None:
        self.calls = 0

    def plan(self, observation):
        self.calls += 1
        goal = np.asarray(observation["state"]["goal"])
        if self.calls <= 2:
            angles = np.linspace(0.1, 0.8, 6)
            return np.column_stack([1.5 * np.sin(angles), 1.5 * (1 - np.cos(angles))])
        return np.linspace([0.0, 0.0], goal, 8)[1:]


def _commands(ep, policy) -> tuple[list[tuple[float, float]], str]:
    runner = EpisodeRunner(ep, AvatarCollider(ep.pedestrians, proxy_poser(ep.pedestrians)))
    sensors = SensorSuite.build(policy.sensors, ep.params, 0)
    sensors.reset(ep)
    policy.reset(ep)
    commands, outcome = [], None
    while outcome is None:
        command = policy.act(sensors.observe(runner.view()))
        commands.append(command)
        outcome = runner.step(*command)
    return commands, outcome


def test_the_tracker_stays_within_the_robot_limits_and_reaches_the_goal() -> None:
    robot = RobotConfig(max_speed_mps=0.6, max_yaw_rate_deg_s=40.0)
    ep = episode(start=(1.0, 2.0), goal=(8.0, 4.0), robot=robot)
    tracker = load_policy("tests.runtime.test_paper_protocol:Arc")
    assert isinstance(tracker, PurePursuitTracker) and tracker.describe()["policy_rate_hz"] == 2.0
    commands, outcome = _commands(ep, tracker)
    v, w = np.array(commands).T
    assert outcome == "success"
    assert (v >= 0).all() and (v <= robot.max_speed_mps + 1e-9).all()
    assert (np.abs(w) <= np.deg2rad(robot.max_yaw_rate_deg_s) + 1e-9).all()
    dt = 1.0 / robot.control_hz
    assert (np.abs(np.diff(np.concatenate([[0.0], v]))) <= tracker.max_accel_mps2 * dt + 1e-9).all()
    assert tracker.policy.calls == pytest.approx(len(commands) / robot.control_hz * 2.0, abs=1.0)  # queried at 2 Hz


class Broken:
    sensors = ("state",)
    rate_hz = 2.0

    def reset(self, episode) -> None:
        pass

    def plan(self, observation):
        return [1.0, 2.0, 3.0]


def test_a_malformed_plan_fails_its_episode_in_one_line() -> None:
    ep = episode()
    tracker = PurePursuitTracker(Broken())
    result = run_episode(ep, tracker, AvatarCollider([], proxy_poser([])))
    assert result.outcome == "error" and "(K, 2..4) waypoints" in result.error and "\n" not in result.error
    with pytest.raises(SongError, match="rate_hz"):
        PurePursuitTracker(type("NoRate", (Broken,), {"rate_hz": 0.0})())


def test_astar_as_a_waypoint_policy_scores_what_astar_scores(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    args = ["eval", "--bench", str(GOLDEN), "--policy", "astar", "--policy", "astar_waypoints", "--out", str(out)]
    assert CliRunner().invoke(app, args).exit_code == 0
    astar, waypoints = (json.loads((out / f"{n}.json").read_text()) for n in ("astar", "astar_waypoints"))
    assert abs(astar["metrics"]["all"]["SR"] - waypoints["metrics"]["all"]["SR"]) <= 5.0
    assert waypoints["policy_kind"] == "waypoints" and waypoints["policy_rate_hz"] == 2.0
    assert waypoints["controller"]["name"] == "regulated_pure_pursuit" and astar["policy_kind"] == "commands"


def test_the_image_goal_is_a_render_at_the_goal_pose() -> None:
    bench = open_benchmark(GOLDEN)
    ep = bench.episode(bench.episode_ids()[0])
    camera = {"width": 48, "height": 36, "backend": "numba"}
    suite = SensorSuite.build(("state", "goal_image"), bench.params, bench.max_pedestrians, {"camera": camera})
    suite.reset(ep)
    runner = EpisodeRunner(ep, make_collider(ep))
    first = suite.observe(runner.view())["goal_image"]
    runner.step(0.5, 0.2)
    assert suite.observe(runner.view())["goal_image"]["rgb"] is first["rgb"]  # rendered once per episode
    other = SensorSuite.build(("rgbd",), bench.params, bench.max_pedestrians, {"camera": camera})
    other.reset(ep)
    view = runner.view()
    at_goal = type(view)(float(ep.t0), goal_pose(ep), view.command, view.episode, view.world)
    reference = other.observe(at_goal)["rgbd"]
    np.testing.assert_array_equal(first["rgb"], reference["rgb"])
    np.testing.assert_array_equal(first["depth"], reference["depth"])
    assert not first["rgb"].flags.writeable
    path = np.vstack([ep.path, ep.goal_xy])
    leg = path[-1] - path[-2] if np.linalg.norm(path[-1] - path[-2]) > 1e-6 else path[-1] - path[-3]
    assert goal_pose(ep).yaw == pytest.approx(np.arctan2(leg[1], leg[0]))


def test_the_avatar_free_ablation_removes_people_and_changes_nothing_else(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    for extra in ([], ["--no-avatars"]):
        args = ["eval", "--bench", str(GOLDEN), "--policy", "astar", "--out", str(out), *extra]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
    main, ablation = (pq.read_table(out / f"{n}.parquet").to_pylist() for n in ("astar", "astar-no-avatars"))
    summary = json.loads((out / "astar-no-avatars.json").read_text())
    assert summary["ablation"] == "no_avatars" and summary["official"] is False
    assert json.loads((out / "astar.json").read_text())["official"] is True
    assert summary["metrics"]["all"]["CR_hum"] == 0.0
    assert {r["policy"] for r in ablation} == {"astar (no avatars)"}
    unaffected = 0
    for a, b in zip(main, ablation, strict=True):
        if a["outcome"] != "human":  # astar is blind to people: only a collision with one changes its run
            assert a["trajectory"] == b["trajectory"] and a["outcome"] == b["outcome"]
            unaffected += 1
    assert unaffected >= 1
    table = (out / "results.md").read_text()
    rows = [line.split("|")[1].strip() for line in table.splitlines()[2:]]
    assert rows.index("astar (no avatars)") == rows.count("astar")  # right after the main rows


def test_eval_runs_only_the_named_episodes(tmp_path: Path) -> None:
    bench = open_benchmark(GOLDEN)
    chosen = bench.episode_ids()[1::2][:2]
    out = tmp_path / "eval"
    args = ["eval", "--bench", str(GOLDEN), "--policy", "straight", "--out", str(out)]
    args += [x for e in chosen for x in ("--episode", e)]
    assert CliRunner().invoke(app, args).exit_code == 0
    assert sorted(r["episode_id"] for r in pq.read_table(out / "straight.parquet").to_pylist()) == sorted(chosen)
    bad = CliRunner().invoke(app, [*args[:-2], "--episode", "nope-000"])
    assert bad.exit_code != 0 and "nope-000" in bad.output


def test_the_env_and_collect_take_the_ablation_too(tmp_path: Path) -> None:
    pytest.importorskip("gymnasium")
    from song.runtime.collect import collect
    from song.runtime.env import SongNavEnv

    env = SongNavEnv(str(GOLDEN), no_avatars=True)
    env.reset(seed=0)
    assert env.runner.episode.pedestrians == [] and env.runner.episode.avatars == []
    summary = collect(str(GOLDEN), "straight", tmp_path / "ds", split="test", limit=1, keep="all", no_avatars=True)
    info = json.loads((Path(summary.out) / "meta" / "info.json").read_text())
    assert info["song"]["ablation"] == "no_avatars"


@pytest.mark.parametrize("name", ["NavDPStandIn", "IPlannerStandIn", "ViNTStandIn", "NoMaDStandIn"])
def test_each_published_profile_runs_end_to_end_through_eval(tmp_path: Path, name: str) -> None:
    out = tmp_path / "eval"
    args = ["eval", "--bench", str(GOLDEN), "--policy", f"tests/runtime/fake_models.py:{name}", "--out", str(out)]
    options = ["--resolution", "64x48", "--limit", "1", "--render-backend", "numba", "--no-avatars"]  # people aside
    result = CliRunner().invoke(app, [*args, *options])
    assert result.exit_code == 0, result.output
    (row,) = pq.read_table(next(out.glob("*.parquet"))).to_pylist()
    assert row["outcome"] != "error", row["error"]
    assert row["steps"] > 1 and row["length"] > 0.1  # the tracked waypoints moved the robot
    summary = json.loads(next(out.glob("*.json")).read_text())
    assert summary["policy_kind"] == "waypoints"


def test_a_stand_in_refuses_the_wrong_image_size_colour_scale_or_depth_units() -> None:
    from song.runtime.adapters import prepare_colour, prepare_depth, profiles
    from tests.runtime.fake_models import StandInModel

    navdp, nomad = StandInModel("navdp"), StandInModel("nomad")
    p = profiles()["navdp"]
    rgb = np.zeros((48, 64, 3), np.uint8)
    rgb[..., 0] = 200  # red
    colour = prepare_colour(rgb, p)
    assert colour.shape == (224, 224, 3) and colour[..., 2].max() == 200 and colour[..., 0].max() == 0  # BGR
    depth = prepare_depth(np.full((48, 64), 2.0, np.float32), p)
    good = {"context": np.stack([colour] * 8), "depth": np.stack([depth] * 8), "goal": np.array([3.0, 1.0], np.float32)}
    assert navdp(good).shape == (24, 2)
    with pytest.raises(ValueError, match="units"):
        navdp({**good, "depth": good["depth"] * 1000.0})
    with pytest.raises(ValueError, match="float32"):
        navdp({**good, "context": good["context"][:, :100]})
    q = profiles()["nomad"]
    frame = prepare_colour(rgb, q)
    assert frame.shape == (96, 96, 3) and -2.2 <= frame.min() and frame.max() <= 2.7  # ImageNet-normalised RGB
    with pytest.raises(ValueError, match="ImageNet"):
        nomad({"context": np.full((4, 96, 96, 3), 200.0, np.float32), "goal_image": frame})
    with pytest.raises(SongError, match="expected"):
        from song.runtime.adapters import decode

        decode(np.zeros((5, 2)), q)
