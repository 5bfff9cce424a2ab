"""The crowd table (``crowd.parquet``) and the per-pedestrian status (``crowd_status.json``).

``crowd.parquet`` columns (:data:`CROWD_COLUMNS`): ``ped_id`` int32, ``frame`` int32 (t = frame / fps),
``t`` float64 s, ``x``, ``y`` float64 m, ``yaw`` float64 rad (CCW from +x), ``speed`` float64 m/s;
sorted by (ped_id, frame); one row per frame of the whole scenario for every kept pedestrian
(standing at the start before departing and at the goal after arriving); zstd; the fps in the
schema metadata. The release's pedestrians table is the same columns with ``scene_id`` in front
(:mod:`song.datasets.bench.schema`), so the two are defined here once.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from song.config import DEFAULT_FPS
from song.datasets.run.layout import CROWD_FILE, CROWD_STATUS_FILE
from song.errors import FormatError
from song.util import write_bytes_atomic, write_json_atomic

CROWD_COLUMNS: tuple[pa.Field, ...] = (
    pa.field("ped_id", pa.int32()),
    pa.field("frame", pa.int32()),
    pa.field("t", pa.float64()),
    pa.field("x", pa.float64()),
    pa.field("y", pa.float64()),
    pa.field("yaw", pa.float64()),
    pa.field("speed", pa.float64()),
)
CROWD_SCHEMA = pa.schema(list(CROWD_COLUMNS))
FPS_KEY = b"fps"


@dataclass(frozen=True)
class CrowdTracks:
    """A scene's crowd as arrays.

    Attributes:
        ids: (P,) int pedestrian ids. t: (F,) s. xy: (P, F, 2) m. yaw: (P, F) rad. speed: (P, F) m/s.
        fps: frames per second.
    """

    ids: np.ndarray
    t: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    fps: int


def _arrow(values: np.ndarray, kind: pa.DataType) -> pa.Array:
    """A null-free Arrow array over a contiguous numpy buffer (``pa.array`` would import pandas: 0.4 s)."""
    return pa.Array.from_buffers(kind, len(values), [None, pa.py_buffer(values)])


def crowd_table(ids: np.ndarray, xy: np.ndarray, yaw: np.ndarray, speed: np.ndarray, fps: int) -> pa.Table:
    """The long table of a crowd given as arrays (ids (P,), xy (P, F, 2), yaw and speed (P, F))."""
    n, frames = yaw.shape if yaw.size else (0, 0)
    frame = np.tile(np.arange(frames, dtype=np.int32), n)
    columns = {
        "ped_id": np.repeat(np.asarray(ids).astype(np.int32), frames),
        "frame": frame,
        "t": frame / fps,
        "x": xy[..., 0].ravel(),
        "y": xy[..., 1].ravel(),
        "yaw": yaw.ravel(),
        "speed": speed.ravel(),
    }
    arrays = [
        _arrow(np.ascontiguousarray(columns[f.name], dtype=f.type.to_pandas_dtype()), f.type) for f in CROWD_SCHEMA
    ]
    return pa.Table.from_arrays(arrays, schema=CROWD_SCHEMA.with_metadata({FPS_KEY: str(fps).encode()}))


def write_crowd(path: str | Path, table: pa.Table) -> None:
    """Write ``crowd.parquet`` atomically (zstd 9; the same table always gives the same bytes)."""
    buffer = io.BytesIO()
    pq.write_table(table, buffer, compression="zstd", compression_level=9)
    write_bytes_atomic(path, buffer.getvalue())


def read_crowd_table(path: str | Path, columns: list[str] | None = None) -> pa.Table:
    """``crowd.parquet`` as an Arrow table, checked against :data:`CROWD_SCHEMA`."""
    path = Path(path)
    try:
        table = pq.read_table(path, columns=columns)
    except (OSError, ValueError) as exc:
        raise FormatError(path, "", f"not a readable Parquet file ({exc})") from None
    for name in columns or CROWD_SCHEMA.names:
        if name not in table.column_names:
            raise FormatError(path, name, "column is missing")
        if table.schema.field(name).type != CROWD_SCHEMA.field(name).type:
            raise FormatError(
                path, name, f"has type {table.schema.field(name).type}, expected {CROWD_SCHEMA.field(name).type}"
            )
    return table


def read_crowd(path: str | Path) -> CrowdTracks:
    """Read ``crowd.parquet`` (a file, or the scene folder holding it) back into arrays."""
    path = Path(path)
    if path.is_dir():
        path = path / CROWD_FILE
    table = read_crowd_table(path)
    fps = int((table.schema.metadata or {}).get(FPS_KEY, str(DEFAULT_FPS).encode()))
    ids = np.unique(table.column("ped_id").to_numpy())
    frames = len(table) // max(1, len(ids))
    if len(ids) * frames != len(table):
        raise FormatError(path, "frame", "every pedestrian must have one row per frame of the scenario")
    col = {name: table.column(name).to_numpy() for name in CROWD_SCHEMA.names}
    shape = (len(ids), frames)
    return CrowdTracks(
        ids=ids,
        t=col["t"][:frames],
        xy=np.stack([col["x"].reshape(shape), col["y"].reshape(shape)], axis=-1),
        yaw=col["yaw"].reshape(shape),
        speed=col["speed"].reshape(shape),
        fps=fps,
    )


class PedestrianStatus(BaseModel):
    """Outcome of one pedestrian in the crowd stage.

    ``arrived``: at the last stop of its routine (``arrival_s``: when it got there, even if it later
    stepped aside to make room for a walker); ``gave_up``: stalled for good on its last leg, it
    stepped out of the way and stands there (its track is kept; ``gave_up_s``: when it gave up, ``last_leg_s``:
    when it set off on that leg);
    ``timeout``: still under way when the simulation ended; ``removed``: it could not start (no
    track; ``reason`` says why).
    """

    model_config = ConfigDict(extra="forbid")
    status: Literal["arrived", "gave_up", "timeout", "removed"]
    reason: str = ""
    arrival_s: float | None = None
    gave_up_s: float | None = Field(default=None, description="when it gave its routine up (``gave_up`` only)")
    last_leg_s: float | None = Field(
        default=None, description="when it set off on the leg it gave up (``gave_up`` only; None in older files)"
    )
    skipped_stops: list[int] = Field(
        default_factory=list,
        description="routine stops (indices into Intent.route()) given up because the way stayed blocked",
    )
    body_radius_m: float | None = Field(
        default=None, description="the body radius it kept others clear by, m (None: removed before it started)"
    )


_STATUS = TypeAdapter(dict[int, PedestrianStatus])


def write_crowd_status(path: str | Path, status: dict[int, dict]) -> None:
    """Write ``crowd_status.json`` (keys are pedestrian ids)."""
    write_json_atomic(path, {str(k): v for k, v in sorted(status.items())})


def read_crowd_status(path: str | Path) -> dict[int, PedestrianStatus]:
    """Read ``crowd_status.json`` (a file or the scene folder holding it)."""
    path = Path(path)
    if path.is_dir():
        path = path / CROWD_STATUS_FILE
    try:
        return _STATUS.validate_python(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, ValidationError) as exc:
        raise FormatError(path, "", f"cannot read the crowd status ({' '.join(str(exc).split())[:200]})") from None
