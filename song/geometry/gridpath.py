"""Geodesic distance fields on occupancy grids and line-of-sight smoothing of grid paths.

Graphs are 8-connected with Euclidean step costs.

Distances run in scipy's compiled Dijkstra (``scipy.sparse.csgraph``) over a graph built once per grid
with vectorised numpy: one call from a start gives the geodesic distance to every cell (many goals per
start are free; the intents stage uses this). Single start-goal paths come from
:mod:`song.geometry.astar`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

SQRT2 = float(np.sqrt(2.0))
_STEPS = ((0, 1, 1.0), (1, 0, 1.0), (1, 1, SQRT2), (1, -1, SQRT2))


@dataclass(frozen=True)
class GridGraph:
    """The 8-connected graph of a boolean grid's True cells (edge weights in cells)."""

    mask: np.ndarray
    index: np.ndarray  # (rows, cols) node id or -1
    cells: np.ndarray  # (n, 2) (row, col) of each node
    matrix: sparse.csr_matrix


def grid_graph(mask: np.ndarray, diagonal: bool = True) -> GridGraph:
    """Build the graph: edges between 8-neighbours that are both True (diagonals need both sides free).

    ``diagonal=False`` keeps only the 4 orthogonal neighbours.
    """
    rows, cols = mask.shape
    index = np.full(mask.shape, -1, dtype=np.int64)
    cells = np.argwhere(mask)
    index[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
    padded = np.pad(mask, 1)
    src, dst, weight = [], [], []
    for dr, dc, w in _STEPS if diagonal else _STEPS[:2]:
        ok = mask & padded[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        if dr and dc:  # no corner cutting: both orthogonal neighbours must be free
            ok &= padded[1 + dr : 1 + dr + rows, 1 : 1 + cols] & padded[1 : 1 + rows, 1 + dc : 1 + dc + cols]
        r, c = np.nonzero(ok)
        src.append(index[r, c])
        dst.append(index[r + dr, c + dc])
        weight.append(np.full(len(r), w))
    src, dst, weight = np.concatenate(src), np.concatenate(dst), np.concatenate(weight)
    n = len(cells)
    matrix = sparse.csr_matrix(
        (np.concatenate([weight, weight]), (np.concatenate([src, dst]), np.concatenate([dst, src]))), shape=(n, n)
    )
    return GridGraph(mask=mask, index=index, cells=cells, matrix=matrix)


def distances_from(graph: GridGraph, start: tuple[int, int], with_path: bool = False, limit: float = np.inf):
    """Geodesic distances (cells) from ``start`` to every node (inf where unreachable or beyond ``limit``).

    Returns ``dist (n,)`` or ``(dist, predecessors)`` when ``with_path``. A finite ``limit`` (cells)
    stops the search early, which makes a query for a nearby goal cheap.
    """
    node = graph.index[start]
    if node < 0:
        raise ValueError(f"start cell {start} is not on the graph")
    # the matrix already holds both directions of every edge, so the directed search is exact and avoids
    # scipy symmetrising (copying) the matrix on every call
    return csgraph.dijkstra(graph.matrix, directed=True, indices=int(node), return_predecessors=with_path, limit=limit)


def distances_from_many(graph: GridGraph, starts: np.ndarray) -> np.ndarray:
    """(S, n) geodesic distances (cells) from several start cells (S, 2) in one compiled call."""
    nodes = graph.index[starts[:, 0], starts[:, 1]]
    if (nodes < 0).any():
        raise ValueError("a start cell is not on the graph")
    return np.atleast_2d(csgraph.dijkstra(graph.matrix, directed=True, indices=nodes))


def line_of_sight(mask: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """True when the segment between cell centres ``a`` and ``b`` (row, col) crosses only True cells.

    Samples every quarter cell along the segment and checks the cells of both neighbouring samples'
    corners, so a diagonal never slips between two blocked cells.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    n = int(np.ceil(np.abs(b - a).max() * 4)) + 1
    t = np.linspace(0.0, 1.0, n)[:, None]
    pts = a + (b - a) * t
    rc = np.concatenate(
        [np.floor(pts + 0.5), np.floor(pts + np.array([0.5, 0.49])), np.floor(pts + np.array([0.49, 0.5]))]
    ).astype(np.int64)
    rows, cols = mask.shape
    if (rc < 0).any() or (rc[:, 0] >= rows).any() or (rc[:, 1] >= cols).any():
        return False
    return bool(mask[rc[:, 0], rc[:, 1]].all())


def shortcut(mask: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Line-of-sight shortcutting: from each kept vertex, jump to the farthest vertex still visible.

    Greedy forward scan (visibility of consecutive path vertices), so the result never crosses a
    False cell (each kept segment passed :func:`line_of_sight`).
    """
    if len(cells) <= 2:
        return cells
    kept = [0]
    i = 0
    while i < len(cells) - 1:
        j = i + 1
        while j + 1 < len(cells) and line_of_sight(mask, cells[i], cells[j + 1]):
            j += 1
        kept.append(j)
        i = j
    return cells[np.array(kept)]


def polyline_length(points: np.ndarray) -> float:
    """Length of a (K, 2) polyline."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0
