"""Grid shortest paths vs networkx, and line-of-sight smoothing never crossing blocked cells."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from song.geometry.astar import astar
from song.geometry.gridpath import distances_from, grid_graph, line_of_sight, polyline_length, shortcut


def octile(a: tuple[int, int], b: tuple[int, int]) -> float:
    dr, dc = abs(a[0] - b[0]), abs(a[1] - b[1])
    return max(dr, dc) + (np.sqrt(2) - 1) * min(dr, dc)


def _nx_graph(mask: np.ndarray) -> nx.Graph:
    """Plain reference: 8-connected grid graph with Euclidean steps and no corner cutting."""
    g = nx.Graph()
    rows, cols = mask.shape
    for r in range(rows):
        for c in range(cols):
            if not mask[r, c]:
                continue
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
                rr, cc = r + dr, c + dc
                if 0 <= rr < rows and 0 <= cc < cols and mask[rr, cc]:
                    if dr and dc and not (mask[r + dr, c] and mask[r, c + dc]):
                        continue
                    g.add_edge((r, c), (rr, cc), weight=float(np.hypot(dr, dc)))
    return g


@pytest.mark.parametrize("seed", range(6))
def test_lengths_equal_networkx_astar(seed: int) -> None:
    rng = np.random.default_rng(seed)
    mask = rng.random((40, 50)) > 0.3
    graph = grid_graph(mask)
    reference = _nx_graph(mask)
    start = tuple(int(v) for v in graph.cells[rng.integers(len(graph.cells))])
    dist = distances_from(graph, start)
    for _ in range(10):
        goal = tuple(int(v) for v in graph.cells[rng.integers(len(graph.cells))])
        if not nx.has_path(reference, start, goal):
            assert not np.isfinite(dist[graph.index[goal]])
            continue
        ref = nx.astar_path_length(reference, start, goal, heuristic=octile, weight="weight")
        assert dist[graph.index[goal]] == pytest.approx(ref, abs=1e-9)
        cells = astar(mask, start, goal)[1]  # the path grading smooths
        assert polyline_length(cells.astype(float)) == pytest.approx(ref, abs=1e-9)
        smooth = shortcut(mask, cells)
        assert (smooth[0] == cells[0]).all() and (smooth[-1] == cells[-1]).all()
        assert all(line_of_sight(mask, a, b) for a, b in zip(smooth[:-1], smooth[1:], strict=True))
        assert polyline_length(smooth.astype(float)) <= ref + 1e-9


def test_line_of_sight_blocks_diagonal_squeeze() -> None:
    mask = np.ones((5, 5), dtype=bool)
    mask[1, 2] = mask[2, 1] = False
    assert not line_of_sight(mask, np.array([1, 1]), np.array([2, 2]))
    assert line_of_sight(mask, np.array([0, 0]), np.array([0, 4]))
