"""A* on grids against networkx (same graph, identical lengths), path validity, statuses, scipy Dijkstra."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from song.geometry.astar import SQRT2, astar


def _nx_graph(free: np.ndarray, diagonal: bool) -> nx.Graph:
    graph = nx.Graph()
    rows, cols = free.shape
    steps = [(0, 1, 1.0), (1, 0, 1.0)] + ([(1, 1, SQRT2), (1, -1, SQRT2)] if diagonal else [])
    for r, c in np.argwhere(free):
        graph.add_node((r, c))
        for dr, dc, w in steps:
            nr, nc = r + dr, c + dc
            if not (0 <= nr < rows and 0 <= nc < cols) or not free[nr, nc]:
                continue
            if dr and dc and not (free[r, nc] and free[nr, c]):
                continue  # no corner cutting
            graph.add_edge((r, c), (nr, nc), weight=w)
    return graph


def _check_path(free: np.ndarray, cells: np.ndarray, diagonal: bool) -> float:
    assert free[cells[:, 0], cells[:, 1]].all()
    steps = np.diff(cells, axis=0)
    assert (np.abs(steps).max(axis=1) == 1).all()
    if not diagonal:
        assert (np.abs(steps).sum(axis=1) == 1).all()
    corner = np.abs(steps).sum(axis=1) == 2
    a = cells[:-1][corner]
    assert free[a[:, 0] + steps[corner, 0], a[:, 1]].all() and free[a[:, 0], a[:, 1] + steps[corner, 1]].all()
    return float(np.where(corner, SQRT2, 1.0).sum())


@pytest.mark.parametrize("diagonal", [True, False])
@pytest.mark.parametrize("seed", range(6))
def test_lengths_equal_networkx_on_random_grids(seed: int, diagonal: bool) -> None:
    rng = np.random.default_rng(seed)
    free = rng.random((30, 40)) > rng.uniform(0.1, 0.35)
    graph = _nx_graph(free, diagonal)
    cells = np.argwhere(free)
    for _ in range(8):
        a, b = (tuple(int(v) for v in cells[rng.integers(len(cells))]) for _ in range(2))
        length, path = astar(free, a, b, diagonal=diagonal)
        try:
            expected = nx.astar_path_length(graph, a, b, weight="weight")
        except nx.NetworkXNoPath:
            assert path is None and length == np.inf
            continue
        assert length == pytest.approx(expected, abs=1e-9)
        assert tuple(path[0]) == a and tuple(path[-1]) == b
        assert _check_path(free, path, diagonal) == pytest.approx(length, abs=1e-9)


def test_statuses_limit_and_blocked_ends() -> None:
    free = np.ones((20, 20), dtype=bool)
    free[:, 10] = False  # a wall splits the grid
    assert astar(free, (0, 0), (0, 19)) == (np.inf, None)
    assert astar(free, (0, 10), (0, 0)) == (np.inf, None)  # blocked start
    assert astar(free, (0, 0), (25, 0)) == (np.inf, None)  # off the grid
    free[5, 10] = True
    length, _ = astar(free, (5, 0), (5, 19))
    assert length == pytest.approx(19.0)
    assert astar(free, (5, 0), (5, 19), limit=10.0)[1] is None  # farther than the limit
    assert astar(free, (3, 3), (3, 3))[0] == 0.0


def test_lengths_equal_scipy_dijkstra_over_the_same_graph() -> None:
    from song.geometry.gridpath import distances_from, grid_graph

    rng = np.random.default_rng(3)
    free = rng.random((25, 25)) > 0.25
    cells = np.argwhere(free)
    pairs = [(tuple(cells[i]), tuple(cells[j])) for i, j in rng.integers(len(cells), size=(6, 2))]
    compiled = [astar(free, a, b)[0] for a, b in pairs]
    graph = grid_graph(free)
    dijkstra = [distances_from(graph, a)[graph.index[b]] for a, b in pairs]
    np.testing.assert_allclose(dijkstra, compiled)


def test_four_connected_search_on_mazes_equals_breadth_first_search() -> None:
    from collections import deque

    rng = np.random.default_rng(4)
    for n in (9, 40, 81):
        free = np.ones((n, n), dtype=bool)  # a serpentine: walls every 4th row, gaps at alternate ends
        for k, r in enumerate(range(3, n - 1, 4)):
            free[r, :] = False
            free[r, (n - 2 if k % 2 == 0 else 0) : (n if k % 2 == 0 else 2)] = True
        free &= rng.random((n, n)) > 0.05  # and some debris
        free[0, 0] = free[n - 1, 0] = True
        dist = np.full((n, n), -1)
        dist[0, 0] = 0
        queue = deque([(0, 0)])
        while queue:
            r, c = queue.popleft()
            for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                if 0 <= r + dr < n and 0 <= c + dc < n and free[r + dr, c + dc] and dist[r + dr, c + dc] < 0:
                    dist[r + dr, c + dc] = dist[r, c] + 1
                    queue.append((r + dr, c + dc))
        length, path = astar(free, (0, 0), (n - 1, 0), diagonal=False)
        if dist[n - 1, 0] < 0:
            assert path is None
            continue
        assert length == dist[n - 1, 0] and len(path) == length + 1
        assert _check_path(free, path, diagonal=False) == length
        assert astar(free, (0, 0), (n - 1, 0), limit=length / 2, diagonal=False)[1] is None
    assert astar(np.ones((3, 3), bool), (1, 1), (1, 1), diagonal=False)[0] == 0.0
