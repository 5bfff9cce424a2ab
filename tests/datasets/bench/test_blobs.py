"""The release's content-addressed blob store."""

from __future__ import annotations

import builtins

from song.datasets.bench import io
from song.datasets.bench.export import manifest_rows
from song.util import sha256_file


def test_a_shared_source_is_read_once_and_stored_once(tmp_path, monkeypatch) -> None:
    asset = tmp_path / "avatar.npz"
    asset.write_bytes(b"x" * 3_000_000)  # more than one copy chunk
    twin = tmp_path / "copy.npz"
    twin.write_bytes(b"x" * 3_000_000)
    reads = []
    real_open = builtins.open

    def counting_open(path, mode="r", *args, **kwargs):
        if "r" in mode and str(path).endswith(".npz"):
            reads.append(str(path))
        return real_open(path, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", counting_open)
    store = io.BlobStore(tmp_path / "release")
    first = store.add(asset)
    assert store.add(asset) == first and store.add(tmp_path / "." / "avatar.npz") == first
    assert len(reads) == 1  # one avatar asset shared by many pedestrians: read once
    assert store.add(twin) == first  # same content, another file: read, stored once
    assert len(reads) == 2
    stored = tmp_path / "release" / first["path"]
    assert stored.read_bytes() == b"x" * 3_000_000
    assert first["sha256"] == sha256_file(stored) and first["bytes"] == 3_000_000
    assert first["path"] == f"blobs/sha256/{first['sha256'][:2]}/{first['sha256']}.npz"
    assert store.add(tmp_path / "missing.npz") is None and store.add(None) is None
    files = sorted(p.relative_to(tmp_path / "release").as_posix() for p in (tmp_path / "release").rglob("*"))
    assert [f for f in files if "." in f.rsplit("/", 1)[-1]] == [first["path"]]  # no staging file left


def test_the_manifest_reuses_stored_digests_and_hashes_everything_else(tmp_path) -> None:
    release = tmp_path / "release"
    store = io.BlobStore(release)
    source = tmp_path / "a.ply"
    source.write_bytes(b"splat")
    blob = store.add(source)
    (release / "data").mkdir()
    (release / "data" / "t.parquet").write_bytes(b"table")
    rows = {r["path"]: r for r in manifest_rows(release, {"data/t.parquet": 3}, store.stored())}
    assert rows[blob["path"]]["sha256"] == sha256_file(release / blob["path"])
    assert rows["data/t.parquet"] == {
        "path": "data/t.parquet",
        "sha256": sha256_file(release / "data" / "t.parquet"),
        "bytes": 5,
        "rows": 3,
    }
    # a stored blob whose file changed size since it was written is hashed again, not trusted
    (release / blob["path"]).write_bytes(b"splat, edited")
    edited = {r["path"]: r for r in manifest_rows(release, {}, store.stored())}[blob["path"]]
    assert edited["sha256"] == sha256_file(release / blob["path"]) and edited["bytes"] == 13
