"""Crowd simulation on the tiny two-room scene: invariants, removals with reasons, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from song.config import SongConfig
from song.datasets.run.intents import Intent, Provenance
from song.datasets.scenes import load_scene_package
from song.geometry.navmesh import Navmesh
from song.pipeline.crowd.avoidance import make_avoidance
from song.pipeline.crowd.navmesh import scene_navmesh
from song.pipeline.crowd.simulate import ASIDE_M, CrowdPlan, plan_crowd
from song.pipeline.crowd.stage import plan_table
from song.util import derive_rng

CFG = SongConfig().crowd
R = CFG.agent_radius_m
SPACING_TOL = 0.01  # m: pairwise centre distance ≥ 2r − 1 cm (the bound)
SPEED_TOL = 1.01  # speed ≤ max + 1 %
ON_MESH_TOL = 1e-6  # m: positions are kept strictly inside the mesh up to rounding


def intent(k: int, start, goal, speed: float = 0.9, depart: float = 0.0) -> Intent:
    return Intent(
        id=k,
        activity="walk",
        start_object="a",
        goal_object="b",
        start_xy=start,
        goal_xy=goal,
        speed=speed,
        depart_time=depart,
        provenance=Provenance(provider="offline", model="test"),
    )


def check_crowd(plan: CrowdPlan, mesh: Navmesh, intents: list[Intent]) -> None:
    """The issue's invariants for one scene's plan."""
    check_tracks(plan.ped_ids, plan.xy, plan.speed, plan.fps, plan.status, mesh, intents)


def check_tracks(ids, xy, speed, fps: int, status: dict, mesh: Navmesh, intents: list[Intent]) -> None:
    """Invariants of joint tracks: ids (P,), xy (P, F, 2) m, speed (P, F) m/s, status per id."""
    if not len(ids):
        return
    d = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    d[np.arange(len(d)), np.arange(len(d))] = np.inf
    assert d.min() >= 2 * R - SPACING_TOL, d.min()
    assert mesh.contains(xy.reshape(-1, 2), tol=ON_MESH_TOL).all()
    by_id = {i.id: i for i in intents}
    max_speed = np.array([by_id[int(k)].speed for k in ids])
    steps = np.linalg.norm(np.diff(xy, axis=1), axis=-1) * fps
    assert (steps <= max_speed[:, None] * SPEED_TOL).all()
    assert (speed <= max_speed[:, None] * SPEED_TOL).all()
    t = np.arange(xy.shape[1]) / fps
    for k, ped in enumerate(ids):
        info = status[int(ped)]
        before = t < by_id[int(ped)].depart_time - 1e-9
        assert np.allclose(xy[k, before], xy[k, 0])  # stands at the start until departure
        if info["status"] == "arrived":
            after = xy[k, t >= info["arrival_s"] - 1e-3]  # (arrival_s is rounded to 0.1 ms)
            goal = np.array(by_id[int(ped)].route()[-1].goal_xy)
            assert np.linalg.norm(after[0] - goal) < 0.5  # at its last goal (or held a step from it)
            # it stands there from then on, or steps aside from it to let a walker pass
            assert (np.linalg.norm(after - goal, axis=1) < 2 * ASIDE_M + 0.05).all()
    assert all(v["reason"] for v in status.values() if v["status"] != "arrived")


def _run(make_scene, intents: list[Intent], seed: int = 0):
    package = load_scene_package(make_scene())
    mesh = scene_navmesh(package, R, CFG.contour_error_m)
    plan = plan_crowd(intents, mesh, make_avoidance(mesh, CFG), CFG, derive_rng(seed, "tiny", "crowd"))
    return plan, mesh


SWAP = [  # two pairs swap rooms through the 1 m door, one pair head-on, plus a walker inside room B
    intent(0, (1.5, 2.0), (6.5, 2.0), 0.9, 0.0),
    intent(1, (6.5, 2.1), (1.5, 2.1), 0.8, 0.3),
    intent(2, (2.0, 3.2), (5.0, 1.0), 1.0, 4.0),
    intent(3, (5.2, 2.9), (2.4, 0.9), 0.6, 5.0),
    intent(4, (4.8, 0.8), (7.3, 2.0), 0.7, 1.0),
]


def test_crowd_through_a_door_keeps_the_invariants(make_scene) -> None:
    plan, mesh = _run(make_scene, SWAP)
    check_crowd(plan, mesh, SWAP)
    arrived = [v for v in plan.status.values() if v["status"] == "arrived"]
    assert len(arrived) == len(SWAP), plan.status
    # headings follow the motion: while walking fast, yaw matches the velocity direction roughly
    v = np.diff(plan.xy, axis=1) * plan.fps
    fast = np.linalg.norm(v, axis=-1) > 0.5
    yaw = np.arctan2(v[..., 1], v[..., 0])
    err = np.abs(np.angle(np.exp(1j * (plan.yaw[:, 1:] - yaw))))
    assert np.median(err[fast]) < 0.3


def test_departures_before_t0_open_the_scenario_mid_walk(make_scene) -> None:
    """Departing at −3 s is the same crowd seen from 3 s on: tracks cut there, arrivals 3 s earlier."""
    base, mesh = _run(make_scene, SWAP)
    early = [i.model_copy(update={"depart_time": i.depart_time - 3.0}) for i in SWAP]
    plan, _ = _run(make_scene, early)
    cut = 3 * CFG.fps
    assert np.array_equal(plan.xy, base.xy[:, cut:]) and np.array_equal(plan.yaw, base.yaw[:, cut:])
    for k, info in plan.status.items():
        assert info["status"] == base.status[k]["status"]
        assert abs(info["arrival_s"] - (base.status[k]["arrival_s"] - 3.0)) < 1e-6
    assert np.linalg.norm(plan.xy[0, 0] - np.asarray(SWAP[0].start_xy)) > 1.0  # on its way at t = 0
    check_crowd(plan, mesh, early)


def test_same_seed_same_bytes_other_seed_other_jitter(make_scene) -> None:
    a, _ = _run(make_scene, SWAP, seed=0)
    b, _ = _run(make_scene, SWAP, seed=0)
    c, _ = _run(make_scene, SWAP, seed=1)
    assert plan_table(a).equals(plan_table(b))
    assert not plan_table(a).equals(plan_table(c))
    assert np.abs(a.xy[:, 0] - c.xy[:, 0]).max() <= 2 * CFG.start_jitter_m  # only the start jitter differs


def test_unplannable_pedestrians_are_removed_with_reasons(make_scene) -> None:
    intents = [
        intent(0, (1.5, 2.0), (6.5, 2.0)),
        intent(1, (1.5, 0.75), (6.0, 3.25), depart=1.0),  # goal inside the sofa, > 0.5 m from free space
        intent(2, (1.6, 2.1), (3.0, 3.0)),  # starts on top of pedestrian 0
    ]
    plan, mesh = _run(make_scene, intents)
    check_crowd(plan, mesh, intents)
    assert plan.status[0]["status"] == "arrived"
    assert plan.status[1]["status"] == "removed" and "navmesh" in plan.status[1]["reason"]
    assert plan.status[2]["status"] == "removed" and "overlaps pedestrian 0" in plan.status[2]["reason"]
    assert list(plan.ped_ids) == [0]


def test_pedestrian_standing_in_a_door_steps_aside(make_scene) -> None:
    intents = [
        intent(0, (3.0, 3.0), (4.0, 2.0), 0.9, 0.0),  # stands in the door from t ≈ 2 s on
        intent(1, (0.8, 1.6), (6.5, 1.5), 0.9, 3.0),  # must pass the door afterwards
    ]
    plan, mesh = _run(make_scene, intents)
    check_crowd(plan, mesh, intents)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    k = list(plan.ped_ids).index(0)
    to_goal = np.linalg.norm(plan.xy[k] - np.array(intents[0].goal_xy), axis=1)
    assert 0.3 < to_goal[-1] < ASIDE_M + 0.1  # it left the door to the walker and stands next to it
    reached = np.flatnonzero(to_goal < 0.05)[0] / plan.fps  # its arrival: when it got to the door, not aside
    assert plan.status[0]["arrival_s"] == pytest.approx(reached, abs=1.5 / plan.fps)


def test_a_walker_still_under_way_when_the_scenario_ends_times_out(make_scene) -> None:
    intents = [intent(0, (1.5, 2.0), (6.5, 2.0), 0.9), intent(1, (2.0, 3.2), (2.5, 3.2), 0.9)]
    cfg = CFG.model_copy(update={"max_duration_s": 4.0})
    mesh = scene_navmesh(load_scene_package(make_scene()), R, CFG.contour_error_m)
    plan = plan_crowd(intents, mesh, make_avoidance(mesh, cfg), cfg, derive_rng(0, "tiny", "crowd"))
    assert plan.status[1]["status"] == "arrived"
    assert plan.status[0] == {
        "status": "timeout", "reason": "did not arrive within 4 s", "arrival_s": None, "skipped_stops": [],
        "body_radius_m": R,
    }  # fmt: skip
    assert (plan.xy.shape[1] - 1) / plan.fps == pytest.approx(4.0, abs=1 / plan.fps)  # cut at the limit


def test_empty_and_single_crowds(make_scene) -> None:
    plan, _ = _run(make_scene, [])
    assert plan.xy.shape[0] == 0 and plan.status == {}
    one = [intent(7, (3.0, 3.0), (3.0, 3.0))]
    plan, mesh = _run(make_scene, one)
    check_crowd(plan, mesh, one)
    assert plan.status[7]["status"] == "arrived"


def _turn(v, wanted, frames: int) -> tuple[np.ndarray, list[float]]:
    """The velocity after ``frames`` frames of :func:`accelerate` toward ``wanted``, and its speed each frame."""
    from song.pipeline.crowd._crowd_kernel import accelerate

    limit, speeds = CFG.max_accel_mps2 / CFG.fps, []
    for _ in range(frames):
        v = accelerate(*v, *wanted, limit)
        speeds.append(float(np.hypot(*v)))
    return np.array(v), speeds


def test_a_walker_keeps_its_speed_through_a_swerve_and_stops_to_turn_back() -> None:
    limit = CFG.max_accel_mps2 / CFG.fps
    swerve = 1.3 * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    v, speeds = _turn((1.3, 0.0), swerve, 15)  # 45° at 2 m/s² sideways: 0.051 rad a frame, 15.3 frames
    assert min(speeds) == pytest.approx(1.3, abs=1e-12)  # a clamp on the vector change dips to 1.20 m/s
    assert 0.0 < np.arctan2(v[1], v[0]) < np.pi / 4
    v, _ = _turn(v, swerve, 3)
    np.testing.assert_allclose(v, swerve, atol=1e-12)
    back, speeds = _turn((1.3, 0.0), (-1.3, 0.0), 60)  # turning back: slow down, then walk the other way
    assert min(speeds) <= limit and np.allclose(back, (-1.3, 0.0))
    v, _ = _turn((0.0, 0.0), (0.0, 1.3), 3)  # setting off: the plain clamp
    np.testing.assert_allclose(v, (0.0, 3 * limit), atol=1e-12)


def test_compiled_acceleration_equals_its_reference_twin() -> None:
    from song.pipeline.crowd._crowd_kernel import accelerate
    from song.pipeline.crowd._simulate_reference import accelerate_reference

    rng = np.random.default_rng(5)
    for _ in range(3000):
        v, w = (rng.normal(0, 1, 2) * rng.choice([0.01, 0.1, 1.0]) for _ in range(2))
        limit, turn = rng.choice([2 / 30, 0.5]), rng.choice([-1.0, 1 / 30, 0.3])
        np.testing.assert_allclose(accelerate(*v, *w, limit, turn), accelerate_reference(v, w, limit, turn), atol=1e-12)


def test_the_sideways_limit_sets_how_fast_a_walker_turns() -> None:
    """With a sideways limit half the speed limit, a 45° swerve at 1.3 m/s takes twice the frames, at full speed."""
    from song.pipeline.crowd._crowd_kernel import accelerate

    limit, v, wanted = 2.0 / 30, (1.3, 0.0), 1.3 * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    for turn, frames in ((limit, 16), (limit / 2, 31)):
        u, n = np.array(v), 0
        while not np.allclose(u, wanted, atol=1e-12):
            u = np.array(accelerate(*u, *wanted, limit, turn))
            assert np.hypot(*u) == pytest.approx(1.3, abs=1e-12)
            n += 1
        assert n == frames
