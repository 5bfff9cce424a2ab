"""Projection of a release onto Habitat's PointNav episode format (``json.gz``).

Frame conversion (ours: right-handed, Z up; Habitat: right-handed, Y up, agent looks along −Z):
a point (x, y, z) becomes (x, z, −y). Our heading θ (CCW from +x about +z) becomes a rotation by
φ = θ − π/2 about Habitat's +Y, because Habitat's identity agent faces −Z, which is our +y (θ = π/2).
Rotations are written [x, y, z, w] as Habitat expects.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from song.datasets.bench.load import Benchmark


def to_habitat_point(xyz: np.ndarray) -> np.ndarray:
    """(..., 3) Z-up points → Habitat Y-up points."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return np.stack([xyz[..., 0], xyz[..., 2], -xyz[..., 1]], axis=-1)


def from_habitat_point(xyz: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_habitat_point`."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return np.stack([xyz[..., 0], -xyz[..., 2], xyz[..., 1]], axis=-1)


def to_habitat_rotation(yaw: float) -> list[float]:
    """Our yaw (rad) → Habitat agent rotation quaternion [x, y, z, w] about +Y."""
    phi = yaw - np.pi / 2
    return [0.0, float(np.sin(phi / 2)), 0.0, float(np.cos(phi / 2))]


def export_habitat(bench: Benchmark, out: str | Path) -> Path:
    """Habitat PointNav episodes; gzip mtime 0.

    ``out`` ending in ``.json.gz``: one file with every episode. Otherwise a folder laid out as
    Habitat's datasets are, one ``<split>/<split>.json.gz`` per split of the release (``test`` only
    for releases before schema 1.3). Returns the file or the folder.
    """
    out = Path(out)
    rows = bench.episodes_table.to_pylist()
    if out.name.endswith(".json.gz"):
        return _write_habitat(bench, rows, out)
    for split in sorted(bench.splits()):
        chosen = [r for r in rows if (r.get("split") or "test") == split]
        _write_habitat(bench, chosen, out / split / f"{split}.json.gz")
    return out


def _write_habitat(bench: Benchmark, rows: list[dict], out: Path) -> Path:
    episodes = []
    for row in rows:
        start = to_habitat_point(np.asarray(row["start_position"]))
        goal = to_habitat_point(np.asarray(row["goal_position"]))
        episodes.append(
            {
                "episode_id": row["episode_id"],
                "scene_id": row["scene_id"],
                "start_position": start.tolist(),
                "start_rotation": to_habitat_rotation(row["start_yaw"]),
                "goals": [{"position": goal.tolist(), "radius": row["goal_radius"]}],
                "info": {
                    "geodesic_distance": row["geodesic_distance"],
                    "difficulty": row["difficulty"],
                    "optimal_time": row["optimal_time"],
                    "song_version": bench.version,
                },
            }
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    payload = json.dumps({"episodes": episodes}, sort_keys=True, allow_nan=False).encode("utf-8")
    with open(out, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0, filename="") as handle:
        handle.write(payload)
    return out
