"""ORCA: the compiled step against its per-agent reference twin, and its invariants (hypothesis)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from song.pipeline.crowd import _orca_reference as ref
from song.pipeline.crowd.orca import OrcaParams, build_obstacles, orca_lines, orca_step

# Tolerances, each with its reason.
TWIN_TOL = 1e-9  # m/s: same float64 formulas; compiled code may fuse or reorder a few operations
LINE_TOL = 1e-9  # half-plane slack (m/s) allowed for a feasible 2-D LP answer: rounding only
SPEED_TOL = 1e-12  # relative: the answer lies in the max-speed disc

PARAMS = OrcaParams(time_step=1 / 30, neighbor_dist=3.0, max_neighbors=10, time_horizon=2.0, time_horizon_obst=2.0)


def _room():
    """An L-shaped room (clockwise boundary: free space inside), two pillars and a thin wall segment."""
    room = np.array([[0, 0], [0, 8], [4, 8], [4, 4], [8, 4], [8, 0]], dtype=float)[::-1]
    pillar = np.array([[1, 1], [2, 1], [2, 2], [1, 2]], dtype=float)
    return [room, pillar, pillar + [0.0, 4.0], np.array([[5.0, 1.0], [6.0, 3.0]])]


def _agents(n: int, seed: int, spread: float = 1.0):
    rng = np.random.default_rng(seed)
    pos = np.column_stack([rng.uniform(0.0, 8.0 * spread, n), rng.uniform(0.0, 4.0 * spread, n)])
    vel, pref = rng.normal(0, 0.7, (n, 2)), rng.normal(0, 1.2, (n, 2))
    return pos, vel, pref, rng.uniform(0.15, 0.35, n), rng.uniform(0.5, 1.5, n)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("n", [1, 2, 9, 40, 130])
@pytest.mark.parametrize("walls", [False, True])
def test_matches_reference_twin(n: int, seed: int, walls: bool) -> None:
    obstacles = build_obstacles(_room()) if walls else None
    args = (*_agents(n, seed), obstacles, PARAMS)
    np.testing.assert_allclose(orca_step(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)


def test_neighbour_grid_keeps_the_all_pairs_answer_with_ties_and_sparse_crowds() -> None:
    """From 64 agents neighbours come from a grid: equal distances (a lattice) and far-flung agents (coarse cells)."""
    lattice = np.stack(np.meshgrid(np.arange(12.0), np.arange(10.0)), -1).reshape(-1, 2) * 0.8  # 120 agents
    _, vel, pref, radii, speeds = _agents(len(lattice), 5)
    args = (lattice, vel, pref, np.full(len(lattice), 0.3), speeds, None, PARAMS)
    np.testing.assert_allclose(orca_step(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)
    args = (*_agents(300, 6, spread=40.0), None, PARAMS)
    np.testing.assert_allclose(orca_step(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)


@pytest.mark.parametrize("seed", range(3))
def test_dense_crowd_uses_the_3d_lp_and_matches_twin(seed: int) -> None:
    """Squeezed agents (2-D LP infeasible) go through linearProgram3, with walls kept hard."""
    pos, vel, pref, radii, speeds = _agents(120, 100 + seed, spread=0.6)
    obstacles = build_obstacles(_room())
    lines = orca_lines(pos, vel, radii, speeds, obstacles, PARAMS)
    infeasible = 0
    for i, (points, dirs, _) in enumerate(lines):
        twin = [(tuple(p), tuple(d)) for p, d in zip(points, dirs, strict=True)]
        fail, _ = ref._lp2(twin, speeds[i], tuple(pref[i]), False)
        infeasible += fail < len(twin)
    assert infeasible >= 10 and sum(k for _, _, k in lines) > 0
    args = (pos, vel, pref, radii, speeds, obstacles, PARAMS)
    np.testing.assert_allclose(orca_step(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)


@pytest.mark.parametrize("seed", range(3))
def test_lines_match_the_reference_twin(seed: int) -> None:
    """The compiled half-planes are the twin's, in the same order (obstacle lines first)."""
    pos, vel, _, radii, speeds = _agents(40, 200 + seed)
    obstacles = build_obstacles(_room())
    for i, (points, dirs, n_obst) in enumerate(orca_lines(pos, vel, radii, speeds, obstacles, PARAMS)):
        p, v = tuple(pos[i]), tuple(vel[i])
        twin = ref._obstacle_lines(p, v, radii[i], speeds[i], obstacles, PARAMS)
        assert n_obst == len(twin)
        for j in ref._agent_neighbours(i, [tuple(q) for q in pos], PARAMS):
            twin.append(ref._agent_line(p, v, radii[i], tuple(pos[j]), tuple(vel[j]), radii[j], PARAMS))
        np.testing.assert_allclose(points, [q for q, _ in twin] or np.zeros((0, 2)), rtol=0, atol=TWIN_TOL)
        np.testing.assert_allclose(dirs, [d for _, d in twin] or np.zeros((0, 2)), rtol=0, atol=TWIN_TOL)


def test_build_obstacles_vertex_order_and_convexity() -> None:
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)  # counter-clockwise: solid
    obs = build_obstacles([square, square[::-1] * 4 - 1.5, np.array([[3.0, 0.0], [3.0, 1.0]])])
    assert obs.convex[:4].all()  # a solid convex obstacle: every vertex convex
    assert not obs.convex[4:8].any()  # a boundary enclosing free space: every vertex reflex
    np.testing.assert_allclose(obs.directions[8], [0.0, 1.0])  # a segment is two-sided
    np.testing.assert_allclose(obs.directions[9], [0.0, -1.0])
    assert obs.next[9] == 8 and obs.prev[8] == 9 and obs.convex[8:].all()
    assert (obs.next[obs.prev] == np.arange(obs.n_vertices)).all()
    assert sorted(obs.subtree)[-1] == obs.n_vertices == obs.subtree[obs.root]  # one tree node per vertex


def test_no_neighbours_returns_preferred_velocity_clipped() -> None:
    pos = np.array([[0.0, 0.0], [100.0, 0.0]])
    pref = np.array([[3.0, 4.0], [0.1, 0.0]])
    out = orca_step(pos, np.zeros((2, 2)), pref, np.full(2, 0.25), np.full(2, 1.0), None, PARAMS)
    np.testing.assert_allclose(out, [[0.6, 0.8], [0.1, 0.0]], rtol=0, atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-5, 5),
    st.floats(-5, 5),
    st.floats(0.1, 2.0),
    st.floats(-10, 10),
    st.floats(-10, 10),
)
def test_lone_agent_gets_its_preferred_velocity_clipped(x: float, y: float, speed: float, u: float, v: float) -> None:
    obstacles = build_obstacles([np.array([[20.0, 20.0], [21.0, 20.0], [21.0, 21.0]])])  # out of reach
    out = orca_step([[x, y]], [[0.3, -0.2]], [[u, v]], [0.25], [speed], obstacles, PARAMS)[0]
    expected = np.array([u, v]) * min(1.0, speed / max(np.hypot(u, v), 1e-300))
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)


@st.composite
def _crowds(draw):
    n = draw(st.integers(1, 12))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-3, 3, (n, 2))
    vel, pref = rng.normal(0, 0.6, (n, 2)), rng.normal(0, 1.5, (n, 2))
    radii, speeds = rng.uniform(0.1, 0.4, n), rng.uniform(0.3, 1.5, n)
    polygons = []
    for _ in range(draw(st.integers(0, 3))):  # random small convex polygons (counter-clockwise)
        k = draw(st.integers(2, 6))
        angles = np.sort(rng.uniform(0, 2 * np.pi, k))
        polygons.append(
            rng.uniform(-3, 3, 2) + rng.uniform(0.2, 1.0) * np.column_stack([np.cos(angles), np.sin(angles)])
        )
    return pos, vel, pref, radii, speeds, build_obstacles(polygons) if polygons else None


def _twin_lines(i: int, pos, vel, radii, speeds, obstacles) -> list:
    """Agent i's half-planes as the reference twin builds them (obstacle lines first)."""
    p, v = tuple(pos[i]), tuple(vel[i])
    lines = ref._obstacle_lines(p, v, radii[i], speeds[i], obstacles, PARAMS) if obstacles else []
    for j in ref._agent_neighbours(i, [tuple(q) for q in pos], PARAMS):
        lines.append(ref._agent_line(p, v, radii[i], tuple(pos[j]), tuple(vel[j]), radii[j], PARAMS))
    return lines


def _worst_slack(lines: list, velocity) -> float:
    """How far (m/s) the velocity lies beyond the half-plane it breaks most (≤ 0 when it breaks none)."""
    return max((ref._det(d, (q[0] - velocity[0], q[1] - velocity[1])) for q, d in lines), default=0.0)


@settings(max_examples=60, deadline=None)
@given(_crowds())
def test_answer_is_in_the_disc_and_every_half_plane_when_feasible(crowd) -> None:
    pos, vel, pref, radii, speeds, obstacles = crowd
    out = orca_step(pos, vel, pref, radii, speeds, obstacles, PARAMS)
    assert (np.linalg.norm(out, axis=1) <= speeds * (1 + SPEED_TOL)).all()
    for i in range(len(pos)):
        lines = _twin_lines(i, pos, vel, radii, speeds, obstacles)
        fail, _ = ref._lp2(lines, speeds[i], tuple(pref[i]), False)
        if fail == len(lines):  # feasible: the answer breaks no half-plane
            assert _worst_slack(lines, out[i]) <= LINE_TOL


PACED = dataclasses.replace(PARAMS, keep_pace=True)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("n", [2, 40, 130])
def test_keep_pace_matches_reference_twin(n: int, seed: int) -> None:
    args = (*_agents(n, 300 + seed), build_obstacles(_room()), PACED)
    np.testing.assert_allclose(orca_step(*args), ref.orca_step_reference(*args), rtol=0, atol=TWIN_TOL)


@settings(max_examples=60, deadline=None)
@given(_crowds())
def test_keep_pace_lengthens_the_answer_within_every_half_plane(crowd) -> None:
    """Kept pace: ORCA's direction, no slower than ORCA's answer, no faster than preferred, no half-plane broken."""
    pos, vel, pref, radii, speeds, obstacles = crowd
    plain = orca_step(pos, vel, pref, radii, speeds, obstacles, PARAMS)
    paced = orca_step(pos, vel, pref, radii, speeds, obstacles, PACED)
    for i in range(len(pos)):
        lines = _twin_lines(i, pos, vel, radii, speeds, obstacles)
        fail, _ = ref._lp2(lines, speeds[i], tuple(pref[i]), False)
        if fail < len(lines):  # infeasible: linearProgram3's answer stands
            np.testing.assert_array_equal(paced[i], plain[i])
            continue
        assert _worst_slack(lines, paced[i]) <= LINE_TOL
        fast, slow = np.hypot(*paced[i]), np.hypot(*plain[i])
        assert abs(plain[i, 0] * paced[i, 1] - plain[i, 1] * paced[i, 0]) <= 1e-9 * max(fast, 1.0)  # same direction
        assert slow - 1e-12 <= fast <= max(slow, min(np.hypot(*pref[i]), speeds[i])) + 1e-9


def test_keep_pace_passes_someone_standing_at_full_speed() -> None:
    """A walker heading 0.3 m past someone standing 2 m ahead turns aside at its speed; RVO2's answer slows it."""
    pos = np.array([[0.0, 0.0], [2.0, 0.3]])
    pref = np.array([[1.3, 0.0], [0.0, 0.0]])
    vel = pref.copy()
    params = dataclasses.replace(PARAMS, static_full_responsibility=True)
    args = (pos, vel, pref, np.array([0.5, 0.25]), np.array([1.3, 0.0]), None)
    plain = orca_step(*args, params)[0]
    paced = orca_step(*args, dataclasses.replace(params, keep_pace=True))[0]
    assert np.hypot(*plain) < 1.28 and plain[1] < 0.0  # turned away and slowed
    np.testing.assert_allclose(np.hypot(*paced), 1.3, rtol=1e-12)
    np.testing.assert_allclose(paced / np.hypot(*paced), plain / np.hypot(*plain), rtol=0, atol=1e-12)
