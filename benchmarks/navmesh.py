"""Navmesh path queries and builds, against the old exact implementation and the real Recast/Detour.

.venv/bin/python benchmarks/navmesh.py [--pairs 200] [--recast] [--grid-pairs 10]

Two parts, one JSON object:

* ``queries``: on each shipped sample scene (the crowd's build: radius and contour error from the
  default config), random start/goal pairs drawn uniformly on the mesh. Per pair the compiled query
  (``Navmesh.find_path``) and the reference twin (``_navmesh_reference.visibility_path_reference``,
  the numpy + scipy implementation the kernel replaced) are timed interleaved, and their lengths
  compared; on ``--grid-pairs`` pairs per scene the 16-connected 0.05 m grid reference gives an
  independent upper bound (ours must not exceed it).
* ``build``: square rooms of 10, 20 and 40 m with 6, 25 and 100 boxes (``benchmarks/crowd.py``'s
  generator), 0.05 m cells, radius 0.25 m: our build against the same build with the reference
  visibility graph (every reflex pair against every wall).

With ``--recast`` both parts also run Recast/Detour (``@recast-navigation/core`` 0.43, the WASM port,
installed with npm into ``~/.cache/song/recast-navigation`` on first use) on the same geometry: the
occupancy grid's blocked cells as boxes, the same cell size and agent radius; build seconds (best of 3)
and ``computePath`` per query, with Detour's lengths against ours.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402
from crowd import occupancy, room  # noqa: E402

from song.config import SongConfig  # noqa: E402
from song.datasets.scenes import load_scene_package  # noqa: E402
from song.geometry._navmesh_reference import (  # noqa: E402
    grid_path_length,
    points_on_mesh,
    visibility_edges_reference,
    visibility_path_reference,
)
from song.geometry.freespace import erode  # noqa: E402
from song.geometry.navmesh import build_navmesh, polyline_length, simplify_polygons, trace_legal  # noqa: E402
from song.pipeline.crowd.navmesh import scene_navmesh  # noqa: E402

RECAST_VERSION = "0.43.1"
RECAST_DIR = Path.home() / ".cache" / "song" / "recast-navigation"
ROOMS = [(10.0, 6), (20.0, 25), (40.0, 100)]
CELL_M, RADIUS_M = 0.05, 0.25


def pairs_in_one_part(mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """n start/goal pairs on the mesh, both ends of a pair on the same connected part."""
    starts, goals = [], []
    while len(starts) < n:
        p, q = points_on_mesh(mesh, 2 * n, rng), points_on_mesh(mesh, 2 * n, rng)
        same = mesh.component[mesh.locate(p)] == mesh.component[mesh.locate(q)]
        starts.extend(p[same])
        goals.extend(q[same])
    return np.array(starts[:n]), np.array(goals[:n])


# ---- Recast/Detour --------------------------------------------------------------------------------
def recast_ready() -> Path:
    """The folder holding the npm packages and the bench script (installed on first use)."""
    if not (RECAST_DIR / "node_modules" / "@recast-navigation" / "core").exists():
        if shutil.which("npm") is None:
            raise SystemExit("--recast needs node and npm")
        RECAST_DIR.mkdir(parents=True, exist_ok=True)
        pkgs = [f"@recast-navigation/{p}@{RECAST_VERSION}" for p in ("core", "generators")]
        subprocess.run(["npm", "install", "--silent", "--prefix", str(RECAST_DIR), *pkgs], check=True)
    shutil.copy(Path(__file__).parent / "recast" / "bench.mjs", RECAST_DIR / "bench.mjs")
    return RECAST_DIR


def grid_geometry(free: np.ndarray, cell: float, origin: tuple[float, float]) -> tuple[list, list]:
    """Floor quad plus one 2 m box per run of blocked cells in a row, Recast's Y-up (x, h, −y)."""
    rows, cols = free.shape
    x0, y0 = origin
    positions = [x0, 0.0, -y0, x0 + cols * cell, 0.0, -y0, x0 + cols * cell, 0.0, -(y0 + rows * cell)]
    positions += [x0, 0.0, -(y0 + rows * cell)]
    indices = [0, 1, 2, 0, 2, 3]
    for r in range(rows):
        line = np.r_[False, ~free[r], False].astype(np.int8)
        edges = np.flatnonzero(np.diff(line))
        top, bottom = y0 + (rows - r) * cell, y0 + (rows - r - 1) * cell
        for c0, c1 in zip(edges[::2], edges[1::2], strict=True):
            a, b = x0 + c0 * cell, x0 + c1 * cell
            base = len(positions) // 3
            for h in (0.0, 2.0):
                positions += [a, h, -bottom, b, h, -bottom, b, h, -top, a, h, -top]
            indices += [base + 4, base + 5, base + 6, base + 4, base + 6, base + 7]  # the top faces up
            for i in range(4):
                j = (i + 1) % 4
                indices += [base + i, base + j, base + 4 + j, base + i, base + 4 + j, base + 4 + i]
    return positions, indices


def run_recast(free, cell, origin, starts, goals, repeats: int = 3) -> dict:
    """Recast build seconds and Detour queries on the grid's geometry (see the module docstring)."""
    folder = recast_ready()
    positions, indices = grid_geometry(free, cell, origin)
    queries = [[float(a[0]), -float(a[1]), float(b[0]), -float(b[1])] for a, b in zip(starts, goals, strict=True)]
    job = {"positions": positions, "indices": indices, "cs": cell, "radius": RADIUS_M, "repeats": repeats}
    job["queries"] = queries
    out = subprocess.run(
        ["node", "bench.mjs"], cwd=folder, input=json.dumps(job), capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)


# ---- parts ----------------------------------------------------------------------------------------
def query_part(pairs: int, grid_pairs: int, recast: bool) -> dict:
    config = SongConfig().crowd
    rng = np.random.default_rng(0)
    scenes = {}
    all_ours, all_ref, worst_ref, worst_grid, detour_diff, detour_ms = [], [], 0.0, -np.inf, [], []
    for folder in sorted((ROOT / "datasets" / "sample_scenes").iterdir()):
        if not (folder / "semantic_map.json").exists():
            continue
        package = load_scene_package(folder)
        mesh = scene_navmesh(package, config.agent_radius_m, config.contour_error_m)
        starts, goals = pairs_in_one_part(mesh, pairs, rng)
        mesh.find_path(starts[0], goals[0])  # warm: kernel arrays, compiled code
        ours_ms, ref_ms, diff = [], [], []
        for a, b in zip(starts, goals, strict=True):
            t0 = time.perf_counter()
            res = mesh.find_path(a, b)
            t1 = time.perf_counter()
            ref = visibility_path_reference(mesh, a, b)
            t2 = time.perf_counter()
            ours_ms.append(1e3 * (t1 - t0))
            ref_ms.append(1e3 * (t2 - t1))
            diff.append(res.length - polyline_length(ref))
        worst_ref = max(worst_ref, float(np.max(np.abs(diff))))
        for a, b in zip(starts[:grid_pairs], goals[:grid_pairs], strict=True):
            worst_grid = max(worst_grid, mesh.find_path(a, b).length - grid_path_length(mesh, a, b))
        row = {
            "reflex": len(mesh.reflex),
            "triangles": len(mesh.triangles),
            "ours_ms_median": round(float(np.median(ours_ms)), 3),
            "ours_ms_p95": round(float(np.percentile(ours_ms, 95)), 3),
            "reference_ms_median": round(float(np.median(ref_ms)), 2),
        }
        if recast:
            grid = package.occupancy
            det = run_recast(grid.free, grid.resolution, grid.origin, starts, goals, repeats=1)
            ours_len = np.array([mesh.find_path(a, b).length for a, b in zip(starts, goals, strict=True)])
            theirs = np.array([np.nan if v is None else v for v in det["lengths"]])
            both = np.isfinite(theirs)
            rel = (theirs[both] - ours_len[both]) / np.maximum(ours_len[both], 1e-9)
            detour_diff.extend(rel)
            detour_ms.extend(det["query_ms"])
            row.update(
                detour_ms_median=round(float(np.median(det["query_ms"])), 3),
                detour_pairs_compared=int(both.sum()),
                detour_minus_ours_median_pct=round(100 * float(np.median(rel)), 3) if len(rel) else None,
            )
        scenes[folder.name] = row
        all_ours.extend(ours_ms)
        all_ref.extend(ref_ms)
    out = {
        "pairs_per_scene": pairs,
        "scenes": scenes,
        "ours_ms_median": round(float(np.median(all_ours)), 3),
        "ours_ms_p95": round(float(np.percentile(all_ours, 95)), 3),
        "reference_ms_median": round(float(np.median(all_ref)), 2),
        "speedup_vs_reference_median": round(float(np.median(all_ref) / np.median(all_ours)), 1),
        "max_abs_length_diff_vs_reference_m": worst_ref,
        "max_ours_minus_grid_reference_m": round(float(worst_grid), 4),
        "targets": {"ours_ms_median": 0.2, "ours_ms_p95": 1.0},
    }
    if recast and detour_diff:
        d = 100 * np.array(detour_diff)
        out["detour"] = {
            "query_ms_median": round(float(np.median(detour_ms)), 3),
            "detour_minus_ours_pct": {
                "median": round(float(np.median(d)), 3),
                "p2.5": round(float(np.percentile(d, 2.5)), 3),
                "p97.5": round(float(np.percentile(d, 97.5)), 3),
                "min": round(float(d.min()), 3),
            },
            "ours_longer_than_detour_by_more_than_0.5pct": int((d < -0.5).sum()),
        }
    return out


def build_part(recast: bool, repeats: int = 3) -> dict:
    out = {}
    for size, count in ROOMS:
        free = occupancy(room(0, size, count), CELL_M, size)
        legal = erode(free, CELL_M, RADIUS_M)
        build_navmesh(legal, CELL_M, (0.0, 0.0), RADIUS_M, CELL_M)  # warm
        ours, vis_ref = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            mesh = build_navmesh(legal, CELL_M, (0.0, 0.0), RADIUS_M, CELL_M)
            t1 = time.perf_counter()
            visibility_edges_reference(mesh)
            t2 = time.perf_counter()
            ours.append(t1 - t0)
            vis_ref.append(t2 - t1)
        t0 = time.perf_counter()
        simplify_polygons(trace_legal(legal, CELL_M, (0.0, 0.0)), CELL_M, min_area=CELL_M**2, margin=CELL_M / 4)
        trace_s = time.perf_counter() - t0
        row = {
            "boxes": count,
            "reflex": len(mesh.reflex),
            "ours_build_s": round(min(ours), 4),
            "of_which_trace_and_simplify_s": round(trace_s, 4),
            "reference_visibility_graph_s": round(min(vis_ref), 4),
        }
        if recast:
            det = run_recast(free, CELL_M, (0.0, 0.0), np.zeros((0, 2)), np.zeros((0, 2)), repeats=repeats)
            row["recast_build_s"] = round(min(det["build_s"]), 4)
            row["ours_speed_vs_recast"] = round(min(det["build_s"]) / min(ours), 2)
        out[f"{size:.0f}m"] = row
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=200, help="random pairs per sample scene")
    parser.add_argument("--grid-pairs", type=int, default=5, help="pairs per scene checked on the fine grid")
    parser.add_argument("--recast", action="store_true", help="also run Recast/Detour (node + npm)")
    args = parser.parse_args()
    emit({"queries": query_part(args.pairs, args.grid_pairs, args.recast), "build": build_part(args.recast)})


if __name__ == "__main__":
    main()
