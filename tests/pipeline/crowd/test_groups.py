"""Pedestrians walking in groups: sizes, routines shared in the intents stage, formation in the crowd."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from song.config import SongConfig
from song.datasets.run.intents import Leg
from song.datasets.scenes import load_scene_package
from song.pipeline.crowd.avoidance import make_avoidance
from song.pipeline.crowd.navmesh import scene_navmesh
from song.pipeline.crowd.simulate import plan_crowd
from song.pipeline.intents.groups import MAX_SIZE, group_sizes
from song.pipeline.intents.stage import generate_intents
from song.util import derive_rng
from tests.pipeline.crowd.test_simulate import CFG, R, check_crowd, intent

SAMPLES = Path(__file__).resolve().parents[3] / "datasets" / "sample_scenes"


def _pair(k: int, lead: tuple, side: tuple, goal_lead: tuple, goal_side: tuple, speed: float = 1.0, depart=0.0):
    """A group of two: pedestrian k leads, k + 1 walks with it."""
    return [
        intent(k, lead, goal_lead, speed, depart).model_copy(update={"group": k}),
        intent(k + 1, side, goal_side, speed, depart).model_copy(update={"group": k}),
    ]


def _plan(make_scene, intents, door: float, grouped: bool = True):
    if not grouped:  # the same people, each alone
        intents = [i.model_copy(update={"group": None}) for i in intents]
    mesh = scene_navmesh(load_scene_package(make_scene(door=door)), R, CFG.contour_error_m)
    plan = plan_crowd(intents, mesh, make_avoidance(mesh, CFG), CFG, derive_rng(0, "groups", "crowd"))
    check_crowd(plan, mesh, intents)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    return plan


def test_group_sizes_follow_the_zero_truncated_poisson_of_the_share() -> None:
    share = 0.5
    sizes = np.array(group_sizes(share, 20_000, np.random.default_rng(0)))
    assert sizes.min() >= 1 and sizes.max() <= MAX_SIZE and sizes.sum() == 20_000
    lam = -math.log(1.0 - share)
    pmf = np.array([lam**n / math.factorial(n) for n in range(1, MAX_SIZE + 1)])
    pmf /= pmf.sum()
    people = pmf * np.arange(1, MAX_SIZE + 1)
    in_groups = 1.0 - people[0] / people.sum()  # ≈ share (exactly, without the cut at MAX_SIZE)
    assert abs(in_groups - share) < 0.03
    assert (sizes[sizes > 1].sum() / sizes.sum()) == pytest.approx(in_groups, abs=0.02)
    assert group_sizes(0.0, 5, np.random.default_rng(0)) == [1] * 5


def test_the_intents_stage_gives_a_group_one_routine_and_spots_side_by_side() -> None:
    package = load_scene_package(SAMPLES / "office_0000")
    config = SongConfig(intents={"group_share": 0.6})
    intents = generate_intents(package, config, derive_rng(1, "office_0000", "intents")).intents
    by_id = {i.id: i for i in intents}
    followers = [i for i in intents if i.group is not None and i.group != i.id]
    assert followers, [i.group for i in intents]
    for f in followers:
        lead = by_id[f.group]
        assert lead.group == lead.id and f.depart_time == lead.depart_time and f.speed == lead.speed
        assert [leg.goal_object for leg in f.route()] == [leg.goal_object for leg in lead.route()]
        assert 0.79 <= np.hypot(*np.subtract(f.start_xy, lead.start_xy)) <= 1.21
        for mine, theirs in zip(f.route(), lead.route(), strict=True):
            assert 0.79 <= np.hypot(*np.subtract(mine.goal_xy, theirs.goal_xy)) <= 2.5  # beside it (or the next spot)
    starts = np.array([i.start_xy for i in intents])
    gaps = np.linalg.norm(starts[:, None] - starts[None], axis=-1) + np.eye(len(starts)) * 9
    assert gaps.min() >= config.intents.min_spawn_separation_m - 1e-6
    alone = generate_intents(package, SongConfig(), derive_rng(1, "office_0000", "intents")).intents
    assert all(i.group is None for i in alone)  # the default: everyone alone


def test_a_pair_walks_abreast_in_an_open_room(make_scene) -> None:
    # the member starts behind its leader (alone, it would walk in its wake) and catches up to its side
    group = _pair(0, (1.5, 2.0), (0.6, 2.0), (6.5, 2.0), (6.5, 0.9))
    plan = _plan(make_scene, group, door=4.0)  # a 4 m "door": one open 8 × 4 m room
    lead, side = plan.xy
    v = np.gradient(lead, axis=0) * plan.fps
    speed = np.hypot(*v.T)
    mid = (lead[:, 0] > 4.0) & (lead[:, 0] < 4.9) & (speed > 0.3)  # caught up, 1.5 m before their stops
    heading = v[mid] / speed[mid, None]
    offset = side[mid] - lead[mid]
    lateral = np.abs(heading[:, 0] * offset[:, 1] - heading[:, 1] * offset[:, 0])
    along = np.abs((heading * offset).sum(axis=1))
    assert mid.sum() > plan.fps / 2 and (lateral > 0.9).all() and (along < 0.5).all()


def test_a_pair_goes_through_a_narrow_door_in_file(make_scene) -> None:
    group = _pair(0, (1.5, 2.0), (1.5, 1.0), (6.5, 2.0), (6.5, 1.0))
    plan = _plan(make_scene, group, door=1.0)
    lead, side = plan.xy
    lead_in, side_in = np.abs(lead[:, 0] - 4.0) < 0.3, np.abs(side[:, 0] - 4.0) < 0.3
    assert lead_in.any() and side_in.any() and not (lead_in & side_in).any()  # one after the other
    assert np.flatnonzero(lead_in)[-1] < np.flatnonzero(side_in)[0]  # the leader first


def test_two_pairs_crossing_do_not_walk_between_each_other(make_scene) -> None:
    east = _pair(0, (1.0, 2.4), (1.0, 1.2), (7.0, 2.4), (7.0, 1.2))
    west = _pair(2, (7.0, 2.0), (7.0, 3.2), (1.0, 2.0), (1.0, 3.2))
    plan = _plan(make_scene, east + west, door=4.0)
    xy = plan.xy
    for pair, others in (((0, 1), (2, 3)), ((2, 3), (0, 1))):
        a, b = xy[pair[0]], xy[pair[1]]
        ab = b - a
        length = np.hypot(*ab.T)
        together = length < 1.6
        for o in others:
            s = ((xy[o] - a) * ab).sum(axis=1) / np.maximum(length**2, 1e-9)
            gap = np.hypot(*(xy[o] - (a + s[:, None] * ab)).T)
            between = together & (s > 0.15) & (s < 0.85) & (gap < 0.35)
            assert not between.any(), np.flatnonzero(between)[:5] / plan.fps


def test_a_group_leaves_a_stop_together(make_scene) -> None:
    # the leader's first stop is near, its member starts farther away: the leader waits for it, both walk on
    group = _pair(0, (2.5, 2.0), (1.2, 3.2), (3.2, 1.2), (2.2, 1.0), speed=0.8)
    legs = [
        [Leg(activity="wait", goal_object="b", goal_xy=goal, dwell_s=2.0),
         Leg(activity="walk", goal_object="c", goal_xy=end)]
        for goal, end in (((3.2, 1.2), (6.5, 2.0)), ((2.2, 1.0), (6.5, 0.9)))
    ]  # fmt: skip
    group = [g.model_copy(update={"legs": leg}) for g, leg in zip(group, legs, strict=True)]
    plan = _plan(make_scene, group, door=4.0)
    speed = plan.speed
    left = []
    for row, stop in enumerate(((3.2, 1.2), (2.2, 1.0))):
        at_stop = np.flatnonzero(np.hypot(*(plan.xy[row] - np.array(stop)).T) < 0.1)
        left.append(at_stop[-1] / plan.fps)  # the last moment it stands at its stop
    assert abs(left[0] - left[1]) < 0.5, left  # they set off together
    assert speed.shape[1] > 0
