"""The golden tiny release pins format v1: it must stay readable, and a fresh export must match it.

Regenerate (only when the format changes on purpose, with a schema version bump):
    SONG_REGEN_GOLDEN=1 .venv/bin/pytest tests/datasets/bench/test_golden.py
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest

import song.datasets.bench as bench
from song.datasets.bench.export import export_bench
from song.datasets.bench.release import verify_release
from song.datasets.bench.schema import SCHEMA_VERSION, TABLES

GOLDEN = Path(__file__).resolve().parents[2] / "artifacts" / "bench_golden"
VERSION = "1.0.0"


def _export(tmp_path: Path) -> Path:
    from tests.datasets.bench.conftest import build_graded_run

    os.environ.setdefault("SOURCE_DATE_EPOCH", "1700000000")
    run = build_graded_run(tmp_path / "golden-run", n_scenes=2, episodes_per_scene=3)
    return export_bench(run, tmp_path / "bench", VERSION, notes="golden tiny release").path


def test_golden_release(tmp_path: Path) -> None:
    fresh = _export(tmp_path)
    if os.environ.get("SONG_REGEN_GOLDEN") == "1":
        shutil.rmtree(GOLDEN / VERSION, ignore_errors=True)
        GOLDEN.mkdir(parents=True, exist_ok=True)
        shutil.copytree(fresh, GOLDEN / VERSION)
    golden = GOLDEN / VERSION
    assert golden.is_dir(), "golden release missing: regenerate with SONG_REGEN_GOLDEN=1"
    assert verify_release(golden).ok
    opened = bench.open(GOLDEN)
    assert opened.info.schema_version.split(".")[0] == SCHEMA_VERSION.split(".")[0]
    assert len(opened) == 6 and len(list(opened.episodes())) == 6
    for rel in [p.relative_to(golden).as_posix() for p in golden.rglob("*.parquet")]:
        old, new = pq.read_table(golden / rel), pq.read_table(fresh / rel)
        name = old.schema.metadata[b"song.table"].decode()
        assert old.schema.remove_metadata() == TABLES[name].remove_metadata() == new.schema.remove_metadata(), rel
        if name != "manifest":  # config_sha256 follows the package's default config, not the format
            keep = [c for c in old.column_names if c != "config_sha256"]
            assert old.select(keep).equals(new.select(keep)), rel
    blobs = {p.relative_to(golden).as_posix() for p in golden.rglob("blobs/**/*") if p.is_file()}
    assert blobs == {p.relative_to(fresh).as_posix() for p in fresh.rglob("blobs/**/*") if p.is_file()}


@pytest.fixture(autouse=True)
def _clock(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
