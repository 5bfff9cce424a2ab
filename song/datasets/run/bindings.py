"""The binding stage's index: ``binding/bindings.json`` (contents in docs/contracts.md)."""

from __future__ import annotations

import json
from pathlib import Path

from pydantic import BaseModel, ConfigDict, ValidationError

from song.datasets.run.layout import BINDINGS_FILE
from song.errors import FormatError
from song.util import write_json_atomic


class BindingRecord(BaseModel):
    """One pedestrian's avatar identity and where its caches are (paths relative to the scene folder)."""

    model_config = ConfigDict(extra="forbid")
    ped_id: int
    avatar_id: str
    asset_path: str
    asset_sha256: str = ""
    cache_file: str
    materialized_file: str | None = None
    height_m: float
    scale: float


class Bindings(BaseModel):
    """``bindings.json``: every bound pedestrian and the size of the pool drawn from."""

    model_config = ConfigDict(extra="forbid")
    pedestrians: list[BindingRecord]
    pool_size: int

    def by_ped(self) -> dict[int, BindingRecord]:
        """Records keyed by pedestrian id."""
        return {record.ped_id: record for record in self.pedestrians}


def write_bindings(path: str | Path, bindings: Bindings) -> None:
    """Write ``bindings.json`` atomically."""
    write_json_atomic(path, bindings.model_dump(mode="json", exclude_none=True))


def read_bindings(path: str | Path) -> Bindings:
    """Read ``bindings.json`` (a file, or the scene folder holding ``binding/bindings.json``)."""
    path = Path(path)
    if path.is_dir():
        path = path / BINDINGS_FILE
    try:
        return Bindings.model_validate(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, ValidationError) as exc:
        raise FormatError(path, "", f"cannot read the bindings ({' '.join(str(exc).split())[:200]})") from None
