"""The crowd stage: intents → joint 30 FPS trajectories (``crowd.parquet``) + per-pedestrian status.

``crowd.parquet`` columns: ``ped_id`` int32, ``frame`` int32 (t = frame / fps), ``t`` float64 s,
``x``, ``y`` float64 m, ``yaw`` float64 rad (CCW from +x), ``speed`` float64 m/s; sorted by
(ped_id, frame); one row per frame of the whole scenario for every kept pedestrian (standing at the
start before departing and at the goal after arriving); zstd; the fps in the schema metadata.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from song.pipeline.chain import StageContext
from song.pipeline.crowd.navmesh import NAVMESH_FILE, crowd_obstacles, save_navmesh, scene_navmesh
from song.pipeline.crowd.simulate import CrowdPlan, plan_crowd
from song.pipeline.intents.model import load_intents
from song.util import write_bytes_atomic, write_json_atomic

CROWD_FILE = "crowd.parquet"
STATUS_FILE = "crowd_status.json"
SCHEMA = pa.schema(
    [
        ("ped_id", pa.int32()),
        ("frame", pa.int32()),
        ("t", pa.float64()),
        ("x", pa.float64()),
        ("y", pa.float64()),
        ("yaw", pa.float64()),
        ("speed", pa.float64()),
    ]
)


def crowd_table(plan: CrowdPlan) -> pa.Table:
    """The long table of a plan (see module docstring)."""
    n, frames = plan.yaw.shape if plan.yaw.size else (0, 0)
    frame = np.tile(np.arange(frames, dtype=np.int32), n)
    columns = {
        "ped_id": np.repeat(plan.ped_ids.astype(np.int32), frames),
        "frame": frame,
        "t": frame / plan.fps,
        "x": plan.xy[..., 0].ravel(),
        "y": plan.xy[..., 1].ravel(),
        "yaw": plan.yaw.ravel(),
        "speed": plan.speed.ravel(),
    }
    arrays = [_arrow(np.ascontiguousarray(columns[f.name], dtype=f.type.to_pandas_dtype()), f.type) for f in SCHEMA]
    return pa.Table.from_arrays(arrays, schema=SCHEMA.with_metadata({b"fps": str(plan.fps).encode()}))


def _arrow(values: np.ndarray, kind: pa.DataType) -> pa.Array:
    """A null-free Arrow array over a contiguous numpy buffer (``pa.array`` would import pandas: 0.4 s)."""
    return pa.Array.from_buffers(kind, len(values), [None, pa.py_buffer(values)])


@dataclass(frozen=True)
class CrowdTracks:
    """A scene's crowd as arrays: ids (P,), t (F,), xy (P, F, 2), yaw (P, F), speed (P, F)."""

    ids: np.ndarray
    t: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray


def load_crowd(scene_dir: str | Path) -> CrowdTracks:
    """Read ``crowd.parquet`` back into arrays."""
    table = pq.read_table(Path(scene_dir) / CROWD_FILE)
    ids = np.unique(table.column("ped_id").to_numpy())
    frames = len(table) // max(1, len(ids))
    col = {name: table.column(name).to_numpy() for name in SCHEMA.names}
    shape = (len(ids), frames)
    return CrowdTracks(
        ids=ids,
        t=col["t"][:frames],
        xy=np.stack([col["x"].reshape(shape), col["y"].reshape(shape)], axis=-1),
        yaw=col["yaw"].reshape(shape),
        speed=col["speed"].reshape(shape),
    )


def crowd_parquet_bytes(plan: CrowdPlan) -> bytes:
    """The plan as ``crowd.parquet`` bytes (zstd; the same plan always gives the same bytes)."""
    buffer = io.BytesIO()
    pq.write_table(crowd_table(plan), buffer, compression="zstd", compression_level=9)
    return buffer.getvalue()


def run_crowd(ctx: StageContext) -> list[str]:
    """Stage entry: build the navmesh, plan the crowd on it, write its files."""
    intents = load_intents(ctx.scene_dir)
    cfg = ctx.config.crowd
    mesh = scene_navmesh(ctx.scene, cfg.agent_radius_m, cfg.contour_error_m)
    plan = plan_crowd(intents.intents, mesh, crowd_obstacles(mesh), cfg, ctx.rng("crowd"))
    save_navmesh(ctx.scene_dir / NAVMESH_FILE, mesh)
    write_bytes_atomic(ctx.scene_dir / CROWD_FILE, crowd_parquet_bytes(plan))
    write_json_atomic(ctx.scene_dir / STATUS_FILE, {str(k): v for k, v in sorted(plan.status.items())})
    return [CROWD_FILE, STATUS_FILE, NAVMESH_FILE]
