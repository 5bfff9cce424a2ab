"""Low-level release I/O: deterministic Parquet files with version metadata, content-addressed blobs."""

from __future__ import annotations

import hashlib
import os
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
from song.util import CHUNK_BYTES

BLOB_STAGING = "blobs/.incoming"  # a blob being copied and hashed; renamed to its address when done


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
        self._by_source: dict[Path, str] = {}

    def add(self, source: Path | None) -> dict | None:
        """Copy ``source`` into the store (once per content) and return its ``{path, sha256, bytes}``.

        Each source file is read once per store: its bytes are hashed as they are copied to a staging
        file, which is then renamed to its content address (or dropped when that content is already
        stored), so the recorded sha256 is the stored copy's by construction. An avatar asset (~3 MB)
        is shared by many pedestrians and copied once.
        """
        if source is None or not source.is_file():
            return None
        key = source.resolve()
        if key not in self._by_source:
            self._by_source[key] = self._copy_in(source)
        return self._known[self._by_source[key]]

    def stored(self) -> dict[str, dict]:
        """``{release-relative path: {path, sha256, bytes}}`` of every blob stored so far."""
        return dict(self._known)

    def _copy_in(self, source: Path) -> str:
        staging = self.root / BLOB_STAGING
        staging.parent.mkdir(parents=True, exist_ok=True)
        digest, size = hashlib.sha256(), 0
        try:
            with open(source, "rb") as src, open(staging, "wb") as dst:
                for block in iter(lambda: src.read(CHUNK_BYTES), b""):
                    digest.update(block)
                    dst.write(block)
                    size += len(block)
            sha = digest.hexdigest()
            rel = BLOB_PATH.format(prefix=sha[:2], sha256=sha, ext="".join(source.suffixes[-1:]))
            if rel not in self._known:  # known content: the staged copy is dropped below
                target = self.root / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(staging, target)
                self._known[rel] = {"path": rel, "sha256": sha, "bytes": size}
        finally:
            staging.unlink(missing_ok=True)
        return rel
