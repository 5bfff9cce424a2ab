"""Dense crowds: doorway swaps, walkers who give up a stop or their routine, the compiled pair loops."""

from __future__ import annotations

import numpy as np
import pytest

from song.datasets.run.intents import Intent, Leg
from song.datasets.scenes import load_scene_package
from song.datasets.scenes.generate import generate_scene
from song.pipeline.crowd._crowd_kernel import _move, near_walkers, overlap_push, preferred_velocities, settle_moves
from song.pipeline.crowd._simulate_reference import (
    near_walkers_reference,
    overlap_push_reference,
    preferred_velocities_reference,
    settle_moves_reference,
)
from song.pipeline.crowd.avoidance import make_avoidance
from song.pipeline.crowd.navmesh import scene_navmesh
from song.pipeline.crowd.simulate import ASIDE_M, plan_crowd
from song.util import derive_rng
from tests.pipeline.crowd.test_simulate import CFG, R, check_crowd, intent

# three people on each side of the door walk through it at once, to spots 0.8 m apart on the far side
SWAP_3V3 = [intent(k, (2.6, 1.3 + 0.7 * k), (6.6, 1.1 + 0.8 * k), 1.0) for k in range(3)] + [
    intent(3 + k, (5.4, 1.3 + 0.7 * k), (1.4, 1.4 + 0.8 * k), 1.0) for k in range(3)
]

DEADLOCK_DOOR = 0.9  # m: the social-force model deadlocks in that swap through a door this wide


def _plan(make_scene, intents, door: float, avoidance: str = "orca", **settings):
    mesh = scene_navmesh(load_scene_package(make_scene(door=door)), R, CFG.contour_error_m)
    cfg = CFG.model_copy(update={"avoidance": avoidance, **settings})
    plan = plan_crowd(intents, mesh, make_avoidance(mesh, cfg), cfg, derive_rng(0, "door", "crowd"))
    return plan, mesh


@pytest.mark.parametrize("door", [1.2, 1.0])
def test_three_against_three_through_a_door_all_arrive(make_scene, door: float) -> None:
    plan, mesh = _plan(make_scene, SWAP_3V3, door)
    check_crowd(plan, mesh, SWAP_3V3)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    assert max(v["arrival_s"] for v in plan.status.values()) < 60.0


def test_a_walker_stalled_for_good_on_its_last_leg_gives_up_and_stands_out_of_the_way(make_scene) -> None:
    # the social-force model deadlocks in this swap through a 0.9 m door; two more walk along the end walls
    intents = SWAP_3V3 + [intent(6, (0.4, 0.6), (0.4, 3.4), 1.0), intent(7, (7.6, 3.4), (7.6, 0.6), 1.0)]
    # the deadlock was built with turns as quick as speed changes (2 m/s²); giving up does not depend on it
    plan, mesh = _plan(make_scene, intents, DEADLOCK_DOOR, "social_force", turn_accel_mps2=2.0)
    check_crowd(plan, mesh, intents)
    assert len(plan.ped_ids) == len(intents)  # nobody is removed once the crowd runs: tracks are never cut
    gave_up = [k for k, v in plan.status.items() if v["status"] == "gave_up"]
    assert gave_up
    t = np.arange(plan.xy.shape[1]) / plan.fps
    for k in gave_up:
        info, row = plan.status[k], list(plan.ped_ids).index(k)
        when = info["gave_up_s"]
        assert "stepped out of the way" in info["reason"] and info["arrival_s"] is None
        assert np.linalg.norm(plan.xy[row, -1] - np.array(intents[k].goal_xy)) > 0.5  # not at its goal
        after = np.linalg.norm(plan.xy[row, t >= when] - plan.xy[row, t >= when][0], axis=1)
        assert after[-1] <= 2 * ASIDE_M + 0.05  # a step out of the way, where it stands
        assert after.max() <= 2 * ASIDE_M + 0.2  # (walkers squeezing past may push it on its way there)
        # it gave up at its first stall, not after its tries: within 5 s of last getting nearer its goal
        assert _no_progress_s(plan, mesh, row, intents[k].goal_xy, when) <= 5.0
    assert t[-1] < CFG.max_duration_s  # and it stands there: the run ends once everyone has finished


def _no_progress_s(plan, mesh, row: int, goal, until: float) -> float:
    """How long pedestrian ``row`` got no nearer ``goal`` (10 cm less path on the navmesh) before ``until``, s."""
    track = plan.xy[row, : int(round(until * plan.fps)) + 1]
    gap = np.array([mesh.find_path(p, np.asarray(goal, float), max_snap=0.5, allow_partial=True).length for p in track])
    best = np.minimum.accumulate(gap)
    behind = np.flatnonzero(best > best[-1] + 0.1)
    return (len(track) - 1 - (behind[-1] + 1 if len(behind) else 0)) / plan.fps


def test_giving_up_in_hindsight_ends_the_dither_and_changes_nothing_before_it(make_scene) -> None:
    # the deadlock above: giving up after its tries, a walker dithers at the door for tens of seconds
    intents = SWAP_3V3 + [intent(6, (0.4, 0.6), (0.4, 3.4), 1.0), intent(7, (7.6, 3.4), (7.6, 0.6), 1.0)]
    late, mesh = _plan(
        make_scene, intents, DEADLOCK_DOOR, "social_force", turn_accel_mps2=2.0, give_up_in_hindsight=False
    )
    plan, _ = _plan(make_scene, intents, DEADLOCK_DOOR, "social_force", turn_accel_mps2=2.0)
    ids = list(plan.ped_ids)
    dither = {k: _no_progress_s(late, mesh, ids.index(k), intents[k].goal_xy, v["gave_up_s"])
              for k, v in late.status.items() if v["status"] == "gave_up"}  # fmt: skip
    assert max(dither.values()) > 20.0  # the dither the rule ends
    first = min(v["gave_up_s"] for v in plan.status.values() if v["status"] == "gave_up")
    same = int(first * plan.fps)  # up to the first decision the two plans are the same, frame for frame
    np.testing.assert_array_equal(plan.xy[:, :same], late.xy[:, :same])
    for k, v in plan.status.items():
        if v["status"] == "gave_up":
            assert _no_progress_s(plan, mesh, ids.index(k), intents[k].goal_xy, v["gave_up_s"]) <= 5.0
    arrived = sum(v["status"] == "arrived" for v in plan.status.values())
    assert arrived >= sum(v["status"] == "arrived" for v in late.status.values()) - 1


def test_someone_dwelling_in_a_doorway_cuts_the_dwell_short_for_a_walker_it_blocks(make_scene) -> None:
    # 0 stops in the 1.0 m door for a minute, then goes back into room A; 1 comes from room B through
    # that door. With no way round, 1's stall makes room: 0 leaves for its next leg early.
    stop = Leg(activity="wait", goal_object="door", goal_xy=(4.0, 2.0), dwell_s=60.0)
    back = Leg(activity="walk", goal_object="corner", goal_xy=(1.2, 3.0))
    dweller = intent(0, (1.0, 2.0), (4.0, 2.0), 0.9).model_copy(update={"legs": [stop, back]})
    walker = intent(1, (7.0, 2.0), (2.5, 1.6), 0.9, depart=8.0)
    plan, mesh = _plan(make_scene, [dweller, walker], 1.0)
    check_crowd(plan, mesh, [dweller, walker])
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    assert not plan.status[0]["skipped_stops"]  # it did stop at the door
    at_door = np.linalg.norm(plan.xy[list(plan.ped_ids).index(0)] - np.array([4.0, 2.0]), axis=-1) < 0.1
    assert 1.0 <= at_door.sum() / plan.fps < 30.0  # ... but not for its minute
    assert plan.status[1]["arrival_s"] < 40.0


def test_compiled_pair_loops_equal_their_reference_twins() -> None:
    rng = np.random.default_rng(7)
    for n in (1, 2, 9, 40):
        pos = rng.uniform(0, 4, (n, 2))
        pos[-1] = pos[0]  # coincident centres
        moving = rng.random(n) < 0.6
        for reach in (0.4, 1.5):
            np.testing.assert_array_equal(near_walkers(pos, moving, reach), near_walkers_reference(pos, moving, reach))
        radius = rng.uniform(0.15, 0.3, n)  # bodies of their own sizes
        push, found = overlap_push(pos, moving, radius, 0.0)
        ref, ref_found = overlap_push_reference(pos, moving, radius, 0.0)
        np.testing.assert_allclose(push, ref, atol=1e-12)
        assert found == ref_found
        # two people standing too close push nobody, so they do not keep the overlap passes going
        standing_pair = np.array([[0.0, 0.0], [0.3, 0.0], [3.0, 0.0]])
        for pushes in (overlap_push, overlap_push_reference):
            assert not pushes(standing_pair, np.array([False, False, True]), np.full(3, 0.3), 0.0)[1]
            assert pushes(standing_pair, np.array([True, False, True]), np.full(3, 0.3), 0.0)[1]
            assert not pushes(standing_pair, np.array([True, False, True]), np.array([0.1, 0.15, 0.3]), 0.0)[1]
        cur, nxt, goal = (pos + rng.normal(0, 2.0, (n, 2)) for _ in range(3))
        has_next, speed = rng.random(n) < 0.5, rng.uniform(0.5, 1.5, n)
        goal[:2] = pos[:2] + 0.1  # slowing down at the goal
        args = (pos, cur, nxt, has_next, goal, speed, moving, radius, 1 / 30)
        np.testing.assert_allclose(preferred_velocities(*args), preferred_velocities_reference(*args), atol=1e-12)


def test_compiled_frame_moves_equal_their_reference_twin(make_scene) -> None:
    # crowds packed into the two rooms and the 1 m door: steps into walls slide, overlaps are pushed apart
    mesh = scene_navmesh(load_scene_package(make_scene(door=1.0)), R, CFG.contour_error_m)
    rng = np.random.default_rng(3)
    tri = mesh.vertices[mesh.triangles]
    dt, limit = 1 / 30, CFG.max_accel_mps2 / 30
    checked = 0
    for n in (1, 6, 30):
        for _ in range(20):
            w = rng.dirichlet(np.ones(3), n)
            pos = np.einsum("nk,nkd->nd", w, tri[rng.integers(len(tri), size=n)])
            vel = rng.normal(0, 0.8, (n, 2))
            moving = rng.random(n) < 0.7
            rows = np.flatnonzero(moving | (rng.random(n) < 0.2))
            wanted = rng.normal(0, 1.5, (len(rows), 2))
            speed = rng.uniform(0.5, 1.8, n)
            radius = rng.uniform(0.7 * R, R, n)
            args = (pos, vel, rows, wanted, moving, speed, dt, limit, radius, 0.002, 3)
            new_pos, new_vel = settle_moves(*args, mesh.move_args())
            ref_pos, ref_vel = settle_moves_reference(mesh, *args)
            np.testing.assert_allclose(new_pos, ref_pos, rtol=0, atol=1e-12)  # the pair loop sums in another order
            np.testing.assert_allclose(new_vel, ref_vel, rtol=0, atol=1e-9)
            assert (new_pos[~moving] == pos[~moving]).all()
            checked += int((np.hypot(*(new_pos - pos).T) > 0).sum())
    assert checked > 300


def test_a_walker_whose_step_is_cancelled_is_not_walked_into(tmp_path) -> None:
    """A leader whose step along a wall is cancelled (sliding lengthened it; the shortened one would leave the
    mesh) is not walked into by its follower: the overlap passes see the cancelled step. The state is a frame
    of a generated restaurant's crowd (seed 21, `paper`) where, until the seventeenth session, the cancel came
    after the passes and left the pair at 0.489 m."""
    package = load_scene_package(generate_scene("gen_restaurant_0004", "restaurant", 1234, tmp_path, splat=False))
    mesh = scene_navmesh(package, R, CFG.contour_error_m)
    pos = np.array([[7.790712824941409, 3.8629661693201345], [8.2851350228926, 4.006095626490314]])
    vel = np.array([[-0.5113709187526361, -0.7065639556714576], [-0.799915480404163, -0.013791607297903852]])
    wanted = np.array([[-0.44042812280468635, -0.7528319258923203], [-0.8071455544414149, -0.02991521163168654]])
    speed, dt = np.array([0.8722, 0.8984]), 1 / 30
    stamp = np.zeros(len(mesh.move_args()[0]), dtype=np.int64)
    step = pos[0] + wanted[0] * dt
    assert _move(*pos[0], *step, speed[0] * dt, stamp, 0, mesh.move_args())[:2] == tuple(pos[0])  # cancelled
    args = (
        pos,
        vel,
        np.arange(2),
        wanted,
        np.ones(2, dtype=bool),
        speed,
        dt,
        CFG.max_accel_mps2 * dt,
        np.full(2, R),
        0.002,
        5,
    )
    new_pos, _ = settle_moves(*args, mesh.move_args())
    assert np.hypot(*(new_pos[0] - new_pos[1])) >= 2 * R
    np.testing.assert_allclose(new_pos, settle_moves_reference(mesh, *args)[0], rtol=0, atol=1e-12)


def test_a_walker_stalled_for_good_gives_up_that_stop_and_walks_on(make_scene) -> None:
    # the social-force deadlock above, but every door walker then has an errand back in its own room: one
    # stalled for good at the door gives the crossing up (its status says which stop) and walks on to it
    def errand(i: Intent) -> Intent:
        back = (i.start_xy[0], 3.4 - 0.1 * i.id)
        legs = [Leg(activity="walk", goal_object="b", goal_xy=i.goal_xy, dwell_s=2.0)]
        legs.append(Leg(activity="walk", goal_object="c", goal_xy=back))
        return i.model_copy(update={"legs": legs})

    door = DEADLOCK_DOOR - 0.05  # at 0.9 m the errands now leave room enough for every crossing
    single, _ = _plan(make_scene, SWAP_3V3, door, "social_force", turn_accel_mps2=2.0)  # the deadlock as built
    intents = [errand(i) for i in SWAP_3V3]
    plan, mesh = _plan(make_scene, intents, door, "social_force", turn_accel_mps2=2.0)
    check_crowd(plan, mesh, intents)
    gave_up = {k for k, v in plan.status.items() if v["skipped_stops"]}
    assert {k for k, v in single.status.items() if v["status"] == "gave_up"} & gave_up  # gave up when it was the last
    walked_on = 0
    for k in gave_up:
        info, row = plan.status[k], list(plan.ped_ids).index(k)
        assert info["skipped_stops"] == [0], info
        far = np.linalg.norm(plan.xy[row] - np.array(intents[k].goal_xy), axis=1).min()
        assert far > 0.5  # it never got to the stop it gave up
        walked_on += info["status"] == "arrived"  # ... and walked on to its errand (one may give that up too)
    assert walked_on >= len(gave_up) - 1 and walked_on
