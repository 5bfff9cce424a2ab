"""Low-level release I/O: deterministic Parquet files with version metadata, content-addressed blobs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from song.datasets.bench.schema import (
    BLOB_PATH,
    META_DATASET_VERSION,
    META_SCHEMA_VERSION,
    META_TABLE,
    PARQUET_COMPRESSION,
    PARQUET_COMPRESSION_LEVEL,
    ROW_GROUP_SIZE,
    SCHEMA_VERSION,
)
from song.util import sha256_file


def write_parquet(path: Path, table: pa.Table, schema: pa.Schema, name: str, dataset_version: str) -> int:
    """Write ``table`` cast to ``schema`` with the release's version stamps; returns the row count.

    Bytes depend only on the rows and the versions (fixed compression, row-group size, no timestamps).
    """
    metadata = {META_DATASET_VERSION: dataset_version.encode(), META_SCHEMA_VERSION: SCHEMA_VERSION.encode()}
    metadata[META_TABLE] = name.encode()
    table = table.select(schema.names).cast(schema).replace_schema_metadata(metadata)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(
        table,
        path,
        compression=PARQUET_COMPRESSION,
        compression_level=PARQUET_COMPRESSION_LEVEL,
        row_group_size=ROW_GROUP_SIZE,
        write_statistics=True,
        store_schema=True,
    )
    return table.num_rows


class BlobStore:
    """Content-addressed files under ``<release>/blobs/sha256/<2 hex>/<hash><ext>``."""

    def __init__(self, release_root: Path) -> None:
        self.root = release_root
        self._known: dict[str, dict] = {}
        self._digests: dict[Path, str] = {}

    def add(self, source: Path | None) -> dict | None:
        """Copy ``source`` into the store (once per content) and return its ``{path, sha256, bytes}``.

        Each source file is hashed once per store: an avatar asset (~3 MB) is shared by many pedestrians,
        and a 500-scene release hashed ~11 GB of them again, once per pedestrian.
        """
        if source is None or not source.is_file():
            return None
        key = source.resolve()
        if key not in self._digests:
            self._digests[key] = sha256_file(source)
        digest = self._digests[key]
        ext = "".join(source.suffixes[-1:])
        rel = BLOB_PATH.format(prefix=digest[:2], sha256=digest, ext=ext)
        if rel not in self._known:
            target = self.root / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
            self._known[rel] = {"path": rel, "sha256": digest, "bytes": target.stat().st_size}
        return self._known[rel]
