"""The release's content-addressed blob store."""

from __future__ import annotations

from song.datasets.bench import io


def test_a_shared_source_is_hashed_once_and_stored_once(tmp_path, monkeypatch) -> None:
    calls = []
    real = io.sha256_file
    monkeypatch.setattr(io, "sha256_file", lambda path: calls.append(path) or real(path))
    asset = tmp_path / "avatar.npz"
    asset.write_bytes(b"x" * 1000)
    twin = tmp_path / "copy.npz"
    twin.write_bytes(b"x" * 1000)
    store = io.BlobStore(tmp_path / "release")
    first = store.add(asset)
    assert store.add(asset) == first and store.add(tmp_path / "." / "avatar.npz") == first
    assert len(calls) == 1  # one avatar asset shared by many pedestrians: read once
    assert store.add(twin) == first  # same content, another file: hashed, stored once
    assert len(calls) == 2
    assert (tmp_path / "release" / first["path"]).read_bytes() == b"x" * 1000
    assert store.add(tmp_path / "missing.npz") is None and store.add(None) is None
