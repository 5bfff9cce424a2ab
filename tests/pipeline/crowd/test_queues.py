"""Narrow passages and the queues at them: doors too narrow to pass in are found, and used one way at a time."""

from __future__ import annotations

import numpy as np
import pytest

from song.datasets.scenes import load_scene_package
from song.pipeline.crowd.avoidance import make_avoidance
from song.pipeline.crowd.navmesh import scene_navmesh
from song.pipeline.crowd.passages import (
    CELL_M,
    LOOK_STEP_M,
    Passages,
    _ahead_kernel,
    find_passages,
    next_crossing,
    path_ahead,
)
from song.pipeline.crowd.simulate import plan_crowd
from song.util import derive_rng
from tests.pipeline.crowd.test_simulate import CFG, R, check_crowd, intent

# four walkers in each room of the two-room scene cross the door, one setting off every second on each side
# (goals clear of the desk and the sofa)
STREAM = [
    intent(k, (1.0 + 0.6 * (k % 2), 0.8 + 0.8 * k), (5.6 - 0.5 * (k % 2), 0.8 + 0.8 * k), 1.0, depart=1.0 * k)
    for k in range(4)
] + [
    intent(4 + k, (7.0 - 0.6 * (k % 2), 0.6 + 0.8 * k), (2.6 - 0.5 * (k % 2), 0.6 + 0.8 * k), 1.0, depart=0.5 + k)
    for k in range(4)
]


QUEUES = CFG.model_copy(update={"queue_at_passages": True})


def _mesh(make_scene, door: float):
    return scene_navmesh(load_scene_package(make_scene(door=door)), R, CFG.contour_error_m)


@pytest.mark.parametrize(("door", "found"), [(0.9, 1), (1.0, 1), (1.1, 0), (1.2, 0)])
def test_a_door_too_narrow_to_pass_in_is_a_passage_with_two_sides(make_scene, door: float, found: int) -> None:
    mesh = _mesh(make_scene, door)
    passages = find_passages(mesh, R)
    assert passages.count == found  # the desk and sofa pockets are dead ends, not passages
    if found:
        assert passages.label_at(np.array([[4.0, 2.0]]))[0] == 0
        room_a, room_b = passages.side_at(0, np.array([[3.4, 2.0], [4.6, 2.0]]))
        assert {room_a, room_b} == {0, 1}
        crossing = next_crossing(passages, np.array([2.0, 2.0]), np.array([[6.0, 2.0]]))
        assert crossing is not None and crossing.sides == (room_a, room_b)
        assert 1.0 < crossing.distance < 2.0
        assert next_crossing(passages, np.array([0.5, 2.0]), np.array([[6.0, 2.0]])) is None  # beyond 2.5 m


def test_a_queue_forms_and_drains_at_a_narrow_door_with_counterflow(make_scene) -> None:
    mesh = _mesh(make_scene, 0.9)
    plan = plan_crowd(STREAM, mesh, make_avoidance(mesh, QUEUES), QUEUES, derive_rng(0, "door", "crowd"))
    check_crowd(plan, mesh, STREAM)  # nobody overlapping, on the mesh, within speed
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    assert max(v["arrival_s"] for v in plan.status.values()) < 40.0  # drained
    passages = find_passages(mesh, R)
    inside = passages.label_at(plan.xy.reshape(-1, 2)).reshape(plan.xy.shape[:2]) == 0
    east = np.array([STREAM[int(k)].goal_xy[0] > 4.0 for k in plan.ped_ids])
    assert not ((inside & east[:, None]).any(0) & (inside & ~east[:, None]).any(0)).any()  # one way at a time
    # someone waited clear of the opening, on its own side, while the door was used the other way
    still = plan.speed < 0.05
    waited = []
    for row, k in enumerate(plan.ped_ids):
        side = np.sign(STREAM[int(k)].start_xy[0] - 4.0)
        clear = np.sign(plan.xy[row, :, 0] - 4.0) == side
        clear &= np.abs(plan.xy[row, :, 0] - 4.0) > 0.5
        others = (inside & (east != east[row])[:, None]).any(0)
        waited.append(int((still[row] & clear & others).sum()))
    assert sum(w >= plan.fps for w in waited) >= 2, waited  # at least two stood for a second or more
    # they wait in place of stepping back and forth: nobody gets more than 1.2 m (along the mesh) farther
    # from its goal than it has been (without queues, 3.3 m: stalls, step-asides and a way back)
    for row, k in enumerate(plan.ped_ids):
        goal = np.array(STREAM[int(k)].goal_xy)
        gap = np.array([mesh.find_path(p, goal, max_snap=0.5, allow_partial=True).length for p in plan.xy[row, ::5]])
        assert (gap - np.minimum.accumulate(gap)).max() < 1.2, k


def test_queues_are_an_option_that_leaves_the_default_crowd_alone(make_scene) -> None:
    assert not CFG.queue_at_passages
    mesh = _mesh(make_scene, 0.9)
    plain = plan_crowd(STREAM, mesh, make_avoidance(mesh, CFG), CFG, derive_rng(0, "door", "crowd"))
    queued = plan_crowd(STREAM, mesh, make_avoidance(mesh, QUEUES), QUEUES, derive_rng(0, "door", "crowd"))
    assert plain.xy.shape != queued.xy.shape or not np.array_equal(plain.xy, queued.xy)


def test_the_compiled_look_along_a_path_matches_its_plain_twin() -> None:
    rng = np.random.default_rng(0)
    labels = rng.integers(-1, 3, (80, 90)).astype(np.int32)
    passages = Passages(labels, np.array([-0.3, -0.2]), 3, [])
    for case in range(500):
        pos, corners = rng.uniform(0, 4, 2), rng.uniform(0, 4, (int(rng.integers(0, 5)), 2))
        if case % 7 == 0 and len(corners):
            corners[0] = pos  # a zero-length leg
        reach = float(rng.uniform(0.0, 6.0))
        points, s = path_ahead(pos, corners, reach)
        got, got_s, got_labels = _ahead_kernel(
            pos, corners.reshape(-1, 2), LOOK_STEP_M, reach, labels, passages.origin, CELL_M
        )
        assert got.shape == points.shape and np.allclose(got, points, atol=1e-12) and np.allclose(got_s, s)
        assert np.array_equal(got_labels, passages.label_at(points))
