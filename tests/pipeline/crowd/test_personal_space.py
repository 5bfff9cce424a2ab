"""Personal space (issue 25): comfort distance in open space, body distance in a narrow corridor, no contact
with someone who has stopped, and routines whose stops are free and reachable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from song.config import SongConfig
from song.datasets.run.intents import Intent, Leg
from song.datasets.scenes import Region, SemanticMap, load_scene_package, write_scene_package
from song.datasets.scenes.model import OccupancySpec
from song.pipeline.crowd.avoidance import make_avoidance
from song.pipeline.crowd.navmesh import scene_navmesh
from song.pipeline.crowd.simulate import MAX_START_WAIT_S, plan_crowd
from song.util import derive_rng
from tests.pipeline.crowd.test_simulate import intent

CFG = SongConfig().crowd
R = CFG.agent_radius_m
RES = 0.05


def room(root: Path, width: float, height: float, scene_id: str) -> Path:
    """An empty walled rectangle (walls 0.1 m thick) whose free interior is ``width`` × ``height`` m."""
    wall = round(0.1 / RES)
    cols, rows = round(width / RES) + 2 * wall, round(height / RES) + 2 * wall
    cells = np.full((rows, cols), 255, dtype=np.uint8)
    cells[:wall], cells[-wall:], cells[:, :wall], cells[:, -wall:] = 0, 0, 0, 0
    w, h = cols * RES, rows * RES
    smap = SemanticMap(
        scene_id=scene_id,
        venue_type="office",
        source="procedural",
        bounds=(0.0, 0.0, w, h),
        occupancy=OccupancySpec(resolution=RES, origin=(0.0, 0.0)),
        regions=[Region(id="hall", type="lobby", polygon=[(0, 0), (w, 0), (w, h), (0, h)])],
        objects=[],
    )
    return write_scene_package(root / scene_id, smap, cells)


def walker(k: int, start, goal, speed: float = 0.9, depart: float = 0.0, legs: list[Leg] | None = None) -> Intent:
    return intent(k, start, goal, speed, depart).model_copy(update={"legs": legs or []})


def simulate(scene: Path, intents: list[Intent], avoidance: str = "orca"):
    cfg = CFG.model_copy(update={"avoidance": avoidance})
    mesh = scene_navmesh(load_scene_package(scene), R, cfg.contour_error_m)
    plan = plan_crowd(intents, mesh, make_avoidance(mesh, cfg), cfg, derive_rng(0, "pair", "crowd"))
    return plan, mesh


def closest(plan) -> float:
    d = np.linalg.norm(plan.xy[:, None] - plan.xy[None], axis=-1)
    d[np.arange(len(d)), np.arange(len(d))] = np.inf
    return float(d.min())


OFFSET = 0.05  # m: lateral offset of a head-on pair (an exactly symmetric pair is broken by the start jitter)


@pytest.mark.parametrize(
    ("name", "a", "b"),
    [
        ("head-on", ((1.0, 4.0), (11.0, 4.0 + OFFSET)), ((11.0, 4.0), (1.0, 4.0 - OFFSET))),
        ("crossing", ((1.0, 4.0), (11.0, 4.0)), ((6.0, 0.8), (6.0, 7.2))),
    ],
)
def test_open_space_pairs_keep_the_comfort_distance(tmp_path: Path, name: str, a, b) -> None:
    scene = room(tmp_path, 12.0, 8.0, "hall")
    intents = [walker(0, *a), walker(1, *b, depart=0.5 if name == "crossing" else 0.0)]
    plan, mesh = simulate(scene, intents)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    assert closest(plan) >= CFG.comfort_distance_m - 0.05, (name, closest(plan))
    assert mesh.contains(plan.xy.reshape(-1, 2), tol=1e-6).all()


def test_head_on_pair_deviates_seconds_before_it_passes(tmp_path: Path) -> None:
    """Anticipation: 2 s before their closest approach (still > 3 m apart) both have swerved over 0.1 m."""
    scene = room(tmp_path, 12.0, 8.0, "hall")
    a, b = ((1.0, 4.0), (11.0, 4.0 + OFFSET)), ((11.0, 4.0), (1.0, 4.0 - OFFSET))
    plan, _ = simulate(scene, [walker(0, *a), walker(1, *b)])
    gap = np.linalg.norm(plan.xy[0] - plan.xy[1], axis=-1)
    early = int(np.argmin(gap)) - 2 * plan.fps
    assert gap[early] > 3.0
    for k, (start, goal) in enumerate((a, b)):
        x, y = plan.xy[k, early]
        line = start[1] + (goal[1] - start[1]) * (x - start[0]) / (goal[0] - start[0])  # its straight way
        assert abs(y - line) > 0.1, (k, y, line)


NARROWEST_MISSED = pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="a known miss: the navmesh strip of a 1.0 m corridor is 0.45 m, too narrow for two bodies",
)


@pytest.mark.parametrize("width", [pytest.param(1.0, marks=NARROWEST_MISSED), 1.1, 1.2])
def test_narrow_corridor_pair_passes_at_body_distance(tmp_path: Path, width: float) -> None:
    """In a corridor too narrow for comfort the pair still passes, shoulder to shoulder but never in contact.

    Not yet in 1.0 m, which issue 25 asks for: its strip of legal centres on the navmesh is 0.45 m, too
    narrow for two bodies (docs/crowd.md, walls), and both walkers give up. The case is kept as a strict
    expected failure, so the day the mesh lets them pass it turns red and the mark must go.
    """
    scene = room(tmp_path, 10.0, width, "corridor")
    y = 0.1 + width / 2  # the corridor's axis (walls 0.1 m thick)
    intents = [walker(0, (0.6, y), (9.6, y)), walker(1, (9.6, y), (0.6, y), depart=0.3)]
    plan, _ = simulate(scene, intents)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    assert closest(plan) >= 2 * R - 0.01


def test_no_contact_with_a_pedestrian_stopped_mid_route(tmp_path: Path) -> None:
    """A walker heading straight through someone dwelling at a stop goes round it, never closer than 2r."""
    scene = room(tmp_path, 12.0, 8.0, "hall")
    stop = Leg(activity="wait", goal_object="b", goal_xy=(6.0, 4.0), geodesic_m=5.0, dwell_s=20.0)
    last = Leg(activity="walk", goal_object="c", goal_xy=(6.0, 7.0), geodesic_m=3.0, dwell_s=0.0)
    intents = [
        walker(0, (1.0, 4.0), (6.0, 4.0), legs=[stop, last]),  # stands at (6, 4) from ~6 s to ~26 s
        walker(1, (1.0, 5.0), (11.0, 3.0), depart=8.0),  # its straight line runs through the stop
    ]
    plan, _ = simulate(scene, intents)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    assert closest(plan) >= 2 * R - 0.01
    k = list(plan.ped_ids).index(0)
    at_stop = np.linalg.norm(plan.xy[k] - np.array([6.0, 4.0]), axis=-1) < 0.1
    assert at_stop.sum() / plan.fps >= 19.0  # it really dwelt there


def test_compiled_anticipation_equals_its_reference_twin() -> None:
    from song.pipeline.crowd._avoidance_reference import anticipate_reference
    from song.pipeline.crowd.avoidance import anticipate

    rng = np.random.default_rng(4)
    for n in (1, 2, 7, 30):
        pos = rng.uniform(0, 8, (n, 2))
        vel = rng.normal(0, 0.8, (n, 2))
        pref = rng.normal(0, 1.0, (n, 2))
        pref[rng.random(n) < 0.3] = 0.0  # some stand
        room = rng.uniform(0, 1, n)
        for reach in (3.0, 50.0):  # some pairs beyond reach, then none
            np.testing.assert_allclose(
                anticipate(pos, vel, pref, 1.0, 4.0, reach),
                anticipate_reference(pos, vel, pref, 1.0, 4.0, reach),
                atol=1e-12,
            )
            np.testing.assert_allclose(
                anticipate(pos, vel, pref, 1.0, 4.0, reach, room),
                anticipate_reference(pos, vel, pref, 1.0, 4.0, reach, room),
                atol=1e-12,
            )
        # no room: no swerve (the speed and direction stay the preferred ones)
        np.testing.assert_allclose(anticipate(pos, vel, pref, 1.0, 4.0, 50.0, np.zeros(n)), pref, atol=1e-12)


def test_swerve_room_by_passage_half_width() -> None:
    """A walker swerves early in full with half the comfort distance beyond its body, not at all where the
    passage is as wide as its body."""
    from song.pipeline.crowd.avoidance import swerve_room

    d = CFG.comfort_distance_m
    assert swerve_room(R + 0.5 * d, R, d) == 1.0 and swerve_room(5.0, R, d) == 1.0
    assert swerve_room(R, R, d) == 0.0 and swerve_room(0.1, R, d) == 0.0
    assert swerve_room(R + 0.25 * d, R, d) == pytest.approx(0.5)


def test_compiled_personal_radii_equal_their_reference_twin() -> None:
    from song.pipeline.crowd._avoidance_reference import personal_radii_reference
    from song.pipeline.crowd.avoidance import personal_radii

    rng = np.random.default_rng(5)
    for n in (1, 2, 9, 40):
        pos = rng.uniform(0, 6, (n, 2))
        radii = np.full(n, R)
        walking = rng.random(n) < 0.7
        half_width = rng.uniform(0.2, 0.8, n)
        comfort = rng.uniform(R, 0.5, n)
        np.testing.assert_array_equal(
            personal_radii(pos, radii, walking, half_width, comfort),
            personal_radii_reference(pos, radii, walking, half_width, comfort),
        )


def test_personal_radius_by_room_neighbours_and_standing() -> None:
    """Half the comfort distance in open space; the passage's half-width less the body in a corridor;
    never overlapping another walker's; fading to the body next to someone standing."""
    from song.pipeline.crowd.avoidance import personal_radii

    radii, walking = np.full(2, R), np.array([True, True])
    far = np.array([[0.0, 0.0], [5.0, 0.0]])
    assert personal_radii(far, radii, walking, np.full(2, 2.0), 0.5).tolist() == [0.5, 0.5]
    assert np.allclose(personal_radii(far, radii, walking, np.full(2, 0.6), 0.5), 0.35)  # 1.2 m corridor
    assert np.allclose(personal_radii(far, radii, walking, np.full(2, 0.5), 0.5), R)  # 1.0 m door: the body
    close = np.array([[0.0, 0.0], [0.7, 0.0]])
    assert np.all(personal_radii(close, radii, walking, np.full(2, 2.0), 0.5) <= 0.35)  # no overlap
    standing = np.array([True, False])
    for gap, expected in ((2.0, 0.5), (1.0, R), (0.6, R)):
        pos = np.array([[0.0, 0.0], [gap, 0.0]])
        got = personal_radii(pos, radii, standing, np.full(2, 2.0), 0.5)
        assert got[1] == R and abs(got[0] - expected) < 0.01, (gap, got)


def test_personal_space_is_given_up_when_held_up_not_when_slowing(tmp_path: Path) -> None:
    """Two slow walkers closing in head-on keep their personal space (they deviate from their preferred
    velocities); the same pair held up (no progress for a while) gives it up and presses on."""
    from song.pipeline.crowd.avoidance import HELD_UP_S

    scene = room(tmp_path, 12.0, 8.0, "hall")
    mesh = scene_navmesh(load_scene_package(scene), R, CFG.contour_error_m)
    avoid = make_avoidance(mesh, CFG)
    pos = np.array([[5.6, 4.0], [6.4, 4.05]])  # 0.8 m apart: inside the comfort distance
    vel, pref = np.array([[0.3, 0.0], [-0.3, 0.0]]), np.array([[1.3, 0.0], [-1.3, 0.0]])
    radii, limits = np.full(2, R), np.full(2, 1.3)

    def deviation(held: float) -> float:
        out = avoid.velocities(pos, vel, pref, radii, limits, np.full(2, held))
        return float(np.linalg.norm(out - pref, axis=1).max())

    assert deviation(0.0) == deviation(HELD_UP_S)  # slowed down but moving on: full personal space
    assert deviation(2 * HELD_UP_S) < deviation(0.0) - 0.05


def test_passage_half_width_is_the_local_thickness(tmp_path: Path) -> None:
    """In a 1.2 m wide corridor the half-width is 0.6 m across the whole width, against the wall too; in a
    5 m room it is the cap everywhere, beside the walls too."""
    from song.pipeline.crowd.avoidance import WallDistance

    for width, expected in ((1.2, 0.6), (5.0, 0.75)):
        mesh = scene_navmesh(load_scene_package(room(tmp_path, width, 8.0, f"w{width}")), R, CFG.contour_error_m)
        walls = WallDistance(mesh)
        x0 = 0.1 + R  # the first point a body centre reaches, beside the wall
        across = np.column_stack([np.linspace(x0 + 0.02, x0 + width - 2 * R - 0.02, 9), np.full(9, 4.0)])
        half = walls.half_width_at(across, 0.75)
        assert np.all(np.abs(half - expected) <= 0.05 + 1e-9), (width, half)


def test_a_pedestrian_about_to_walk_off_lets_a_passer_go_by(tmp_path: Path) -> None:
    """Due to leave its spot as a walker comes by within the comfort distance, it waits until the walker has
    passed (people do not step out into someone's way), then leaves."""
    scene = room(tmp_path, 12.0, 1.5, "aisle")  # too narrow to pass someone standing at the comfort distance
    due = 5.0
    intents = [walker(0, (6.0, 1.25), (1.0, 1.0), depart=due), walker(1, (1.0, 0.6), (11.0, 0.6))]
    plan, _ = simulate(scene, intents)
    assert all(v["status"] == "arrived" for v in plan.status.values()), plan.status
    k, p = list(plan.ped_ids).index(0), list(plan.ped_ids).index(1)
    left = int(np.flatnonzero(np.linalg.norm(plan.xy[k] - plan.xy[k, 0], axis=-1) > 0.01)[0])
    passer = plan.xy[p, round(due * plan.fps) :]
    assert np.linalg.norm(passer - plan.xy[k, 0], axis=-1).min() < CFG.comfort_distance_m  # it came by close
    assert due + 0.2 < left / plan.fps <= due + MAX_START_WAIT_S + 0.1
    assert plan.xy[p, left, 0] > plan.xy[k, 0, 0]  # it left once the walker was past
    assert closest(plan) >= 2 * R - 0.01
