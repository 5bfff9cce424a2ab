"""ORCA against RVO2 itself (pyrvo wraps RVO2's C++ ``RVOSimulator``; it computes in float32).

Both simulators get the same parameters, the same time step and the same preferred-velocity rule
(toward the goal, capped at the max speed, computed from each simulator's own positions); ours moves
agents as RVO2 does (p += v dt after all velocities are computed).
"""

from __future__ import annotations

import numpy as np
import pytest

from song.pipeline.crowd.orca import ObstacleSet, OrcaParams, build_obstacles, orca_lines, orca_step

pyrvo = pytest.importorskip("pyrvo")

RADIUS, SPEED = 0.25, 1.0
# Tolerances, each with its reason.
POS_TOL = 1e-3  # m, per step over a whole run (the bound; float32 rounding grows along a run)
F32_VEL_TOL = 1e-4  # m/s, one step from identical states: only float32 vs float64 rounding differs
F32_LINE_TOL = 1e-4  # ORCA line points (m/s) and unit directions, float32 vs float64
F32_VERTEX_TOL = 1e-5  # m, obstacle vertices (split points) computed in float32 by RVO2
ARRIVAL_REL_TOL = 0.05  # circle runs: arrival times within 5 %
MIN_DIST_TOL = 0.005  # m, circle runs: minimum centre distances within 5 mm
ARRIVED = 0.01  # m from the goal counts as arrived

SQUARE = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])  # counter-clockwise: solid


def _rvo2(params: OrcaParams, start: np.ndarray, polygons=(), velocities=None):
    sim = pyrvo.RVOSimulator(
        params.time_step,
        params.neighbor_dist,
        params.max_neighbors,
        params.time_horizon,
        params.time_horizon_obst,
        RADIUS,
        SPEED,
    )
    for i, p in enumerate(start):
        if velocities is None:
            sim.add_agent((float(p[0]), float(p[1])))
        else:
            v = velocities[i]
            args = (params.neighbor_dist, params.max_neighbors, params.time_horizon, params.time_horizon_obst)
            sim.add_agent((float(p[0]), float(p[1])), *args, RADIUS, SPEED, (float(v[0]), float(v[1])))
    for poly in polygons:
        sim.add_obstacle([(float(x), float(y)) for x, y in poly])
    if len(polygons):
        sim.process_obstacles()
    return sim


def _pref(pos: np.ndarray, goals: np.ndarray, dt: float) -> np.ndarray:
    """Toward the goal, reaching it in one step when close, capped at the max speed."""
    to_goal = goals - pos
    dist = np.linalg.norm(to_goal, axis=1, keepdims=True)
    return to_goal / dt * np.minimum(1.0, SPEED * dt / np.maximum(dist, 1e-12))


def _simulate(ours: bool, params: OrcaParams, start, goals, steps: int, polygons=()) -> np.ndarray:
    """Positions (steps + 1, N, 2) of a run of either simulator."""
    n = len(start)
    pos, vel = np.asarray(start, dtype=np.float64).copy(), np.zeros((n, 2))
    if ours:
        obstacles = build_obstacles(list(polygons)) if len(polygons) else None
    else:
        sim = _rvo2(params, pos, polygons)
    history = [pos.copy()]
    for _ in range(steps):
        pref = _pref(pos, goals, params.time_step)
        if ours:
            vel = orca_step(pos, vel, pref, np.full(n, RADIUS), np.full(n, SPEED), obstacles, params)
            pos = pos + vel * params.time_step
        else:
            for i in range(n):
                sim.set_agent_pref_velocity(i, (float(pref[i, 0]), float(pref[i, 1])))
            sim.do_step()
            pos = np.array([sim.get_agent_position(i).to_tuple() for i in range(n)])
        history.append(pos.copy())
    return np.array(history)


def _arrival_steps(history: np.ndarray, goals: np.ndarray) -> np.ndarray:
    arrived = np.linalg.norm(history - goals[None], axis=-1) < ARRIVED
    return np.where(arrived.any(axis=0), arrived.argmax(axis=0), -1)


def _min_distance(history: np.ndarray) -> float:
    d = np.linalg.norm(history[:, :, None] - history[:, None], axis=-1)
    n = history.shape[1]
    d[:, np.arange(n), np.arange(n)] = np.inf
    return float(d.min())


def test_two_agents_head_on_with_1cm_offset() -> None:
    params = OrcaParams(1 / 30, 5.0, 10, 2.0, 2.0)
    start = np.array([[-3.0, 0.0], [3.0, 0.01]])
    goals = np.array([[3.0, 0.0], [-3.0, 0.01]])
    ours, rvo = (_simulate(flag, params, start, goals, 240) for flag in (True, False))
    gap = np.abs(ours - rvo).max()
    assert gap < POS_TOL, f"max per-step position difference {gap:.2e} m"
    assert (_arrival_steps(ours, goals) >= 0).all()
    assert _min_distance(ours) > 2 * RADIUS - 0.005  # they swerve: RVO2 allows a few mm of overlap


def test_agents_passing_a_square_obstacle() -> None:
    params = OrcaParams(1 / 30, 3.0, 10, 3.0, 3.0)
    start = np.array([[-5, 1.05], [-5.5, -1.1], [5, 1.15], [5.2, -1.3], [1.3, 5.0], [-1.2, -5.3]])
    goals = np.array([[5, 1.05], [5.5, -1.1], [-5, 1.15], [-5.2, -1.3], [1.3, -5.0], [-1.2, 5.3]])
    ours, rvo = (_simulate(flag, params, start, goals, 600, [SQUARE]) for flag in (True, False))
    gap = np.abs(ours - rvo).max()
    assert gap < POS_TOL, f"max per-step position difference {gap:.2e} m"
    assert (_arrival_steps(ours, goals) >= 0).all() and (_arrival_steps(rvo, goals) >= 0).all()
    clearance = (np.abs(ours) - 1.0).max(axis=-1).min()  # distance to the square (outside it)
    assert clearance > RADIUS - 0.01


@pytest.mark.parametrize(("n", "circle_radius", "seed"), [(8, 4.0, 0), (20, 6.0, 1)])
def test_circle_to_antipodes(n: int, circle_radius: float, seed: int) -> None:
    # RVO2's circle examples use long horizons; with 2–3 s eight agents lock in a pinwheel in both
    # simulators alike (RVO2's known deadlock), which is not a difference between them.
    params = OrcaParams(1 / 30, 5.0, 10, 5.0, 2.0)
    rng = np.random.default_rng(seed)
    angles = 2 * np.pi * np.arange(n) / n
    jitter_dir = rng.uniform(0, 2 * np.pi, n)
    jitter = rng.uniform(0.01, 0.05, n)[:, None] * np.column_stack([np.cos(jitter_dir), np.sin(jitter_dir)])
    start = circle_radius * np.column_stack([np.cos(angles), np.sin(angles)]) + jitter
    goals = -start
    ours, rvo = (_simulate(flag, params, start, goals, 900) for flag in (True, False))
    t_ours, t_rvo = _arrival_steps(ours, goals), _arrival_steps(rvo, goals)
    assert (t_ours >= 0).all() and (t_rvo >= 0).all(), "every agent arrives in both"
    assert np.abs(t_ours / t_rvo - 1).max() <= ARRIVAL_REL_TOL
    assert abs(_min_distance(ours) - _min_distance(rvo)) < MIN_DIST_TOL


def _float32_sensitivity(args: tuple, agent: int, rng: np.random.Generator) -> float:
    """How far our own float64 answer for one agent moves when the state is perturbed by float32 rounding."""
    pos, vel, pref, *rest = args
    base = orca_step(pos, vel, pref, *rest)[agent]
    eps = np.finfo(np.float32).eps / 2  # relative rounding of a float32 number
    moved = [
        orca_step(
            pos * (1 + rng.uniform(-eps, eps, pos.shape)), vel * (1 + rng.uniform(-eps, eps, vel.shape)), pref, *rest
        )
        for _ in range(10)
    ]
    return max(float(np.abs(m[agent] - base).max()) for m in moved)


def test_one_step_from_identical_states_differs_only_by_float32_rounding() -> None:
    """Along RVO2's own dense run, our step from RVO2's state gives RVO2's next velocity.

    Where the gap exceeds float32 noise, our own answer moves as much when we round the state the
    way float32 does: the step is ill-conditioned there (agents overlapping or grazing tangents), and
    the gap is rounding, not a difference in the algorithm.
    """
    params = OrcaParams(1 / 30, 5.0, 10, 5.0, 2.0)
    n = 20
    angles = 2 * np.pi * np.arange(n) / n
    start = 3.0 * np.column_stack([np.cos(angles), np.sin(angles)])
    start += np.random.default_rng(3).uniform(-0.05, 0.05, (n, 2))
    goals = -start
    polygons = [SQUARE * 0.4 + [0.0, 2.0]]
    sim = _rvo2(params, start, polygons)
    obstacles = build_obstacles(polygons)
    rng = np.random.default_rng(0)
    gaps, ill_conditioned, squeezed = [], 0, 0
    for _ in range(300):
        pos = np.array([sim.get_agent_position(i).to_tuple() for i in range(n)])
        vel = np.array([sim.get_agent_velocity(i).to_tuple() for i in range(n)])
        pref = _pref(pos, goals, params.time_step).astype(np.float32).astype(np.float64)
        for i in range(n):
            sim.set_agent_pref_velocity(i, (float(pref[i, 0]), float(pref[i, 1])))
        sim.do_step()
        theirs = np.array([sim.get_agent_velocity(i).to_tuple() for i in range(n)])
        args = (pos, vel, pref, np.full(n, RADIUS), np.full(n, SPEED), obstacles, params)
        ours = orca_step(*args)
        gap = np.abs(ours - theirs).max(axis=1)
        gaps.append(gap.max())
        squeezed += bool((np.linalg.norm(ours, axis=1) < 0.5 * np.linalg.norm(pref, axis=1)).any())
        if gap.max() > F32_VEL_TOL:
            agent = int(gap.argmax())
            assert gap[agent] < 3 * _float32_sensitivity(args, agent, rng), f"gap {gap[agent]:.2e} m/s"
            ill_conditioned += 1
    assert np.median(gaps) < 1e-6 and ill_conditioned <= 5, (np.median(gaps), ill_conditioned)
    assert squeezed > 10  # the run is dense: agents are squeezed, not just walking past


def _lines_of(lines, agent: int) -> tuple[np.ndarray, np.ndarray]:
    points, directions, _ = lines[agent]
    return points, directions


def _scene() -> tuple[list[np.ndarray], ObstacleSet]:
    room = np.array([[0, 0], [0, 8], [4, 8], [4, 4], [8, 4], [8, 0]], dtype=float)[::-1]  # clockwise: free inside
    pillar = np.array([[1, 1], [2, 1], [2, 2], [1, 2]], dtype=float)
    polygons = [room, pillar, pillar + [0.0, 4.0], np.array([[5.0, 1.0], [6.0, 3.0]])]
    return polygons, build_obstacles(polygons)


def test_obstacle_vertices_and_edge_splits_match_rvo2() -> None:
    polygons, obstacles = _scene()
    sim = _rvo2(OrcaParams(1 / 30, 5.0, 10, 2.0, 2.0), np.zeros((1, 2)), polygons)
    n_vertices = sim.get_num_obstacle_vertices()
    assert obstacles.n_vertices == n_vertices > sum(len(p) for p in polygons)  # some edges were split
    theirs = np.array([sim.get_obstacle_vertex(v).to_tuple() for v in range(n_vertices)])
    np.testing.assert_allclose(obstacles.points, theirs, atol=F32_VERTEX_TOL)
    assert obstacles.next.tolist() == [sim.get_next_obstacle_vertex(v) for v in range(n_vertices)]
    assert obstacles.prev.tolist() == [sim.get_prev_obstacle_vertex(v) for v in range(n_vertices)]


@pytest.mark.parametrize("seed", range(3))
def test_neighbours_and_orca_lines_match_rvo2(seed: int) -> None:
    polygons, obstacles = _scene()
    params = OrcaParams(1 / 30, 3.0, 6, 2.0, 2.0)
    rng = np.random.default_rng(seed)
    n = 40
    pos = np.column_stack([rng.uniform(0.3, 7.7, n), rng.uniform(0.3, 3.7, n)]).astype(np.float32).astype(float)
    vel = rng.normal(0, 0.6, (n, 2)).astype(np.float32).astype(float)
    sim = _rvo2(params, pos, polygons, velocities=vel)
    for i in range(n):
        sim.set_agent_pref_velocity(i, (0.0, 0.0))
    sim.do_step()  # the lines are built from the state before the move
    lines = orca_lines(pos, vel, np.full(n, RADIUS), np.full(n, SPEED), obstacles, params)
    n_obstacle_lines = 0
    for i in range(n):
        count = sim.get_agent_num_orca_lines(i)
        theirs = [sim.get_agent_orca_line(i, k) for k in range(count)]
        points, dirs = _lines_of(lines, i)
        assert len(points) == count, f"agent {i}"
        np.testing.assert_allclose(dirs, [t[0] for t in theirs], atol=F32_LINE_TOL)
        np.testing.assert_allclose(points, [t[1] for t in theirs], atol=F32_LINE_TOL)
        n_obstacle_lines += count - sim.get_agent_num_agent_neighbors(i)
    assert n_obstacle_lines > n  # the walls and pillars are in play


def test_agents_with_speed_limit_zero_get_rvo2s_answer() -> None:
    """Someone standing (speed limit 0) gets 0, as from RVO2's programs, which our step skips for them.

    The others' answers still see them (as neighbours), also as in RVO2.
    """
    params = OrcaParams(1 / 30, 5.0, 10, 2.0, 2.0)
    rng = np.random.default_rng(5)
    n = 12
    pos = rng.uniform(0.0, 3.0, (n, 2))
    vel = rng.normal(0.0, 0.5, (n, 2))
    pref = rng.normal(0.0, 1.0, (n, 2))
    speeds = np.where(np.arange(n) % 3 == 0, 0.0, SPEED)
    sim = _rvo2(params, pos, velocities=vel)
    for i in range(n):
        sim.set_agent_max_speed(i, float(speeds[i]))
        sim.set_agent_pref_velocity(i, (float(pref[i, 0]), float(pref[i, 1])))
    sim.do_step()
    theirs = np.array([sim.get_agent_velocity(i).to_tuple() for i in range(n)])
    ours = orca_step(pos, vel, pref, np.full(n, RADIUS), speeds, None, params)
    assert np.all(ours[speeds == 0.0] == 0.0)
    np.testing.assert_allclose(ours, theirs, atol=F32_VEL_TOL)
