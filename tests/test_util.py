"""The deflated .npz writer: what numpy and zipfile read back, stable bytes, the zipfile fallback."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from song import util


def arrays() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {
        "poses": rng.normal(size=(300, 156)),
        "frame": np.arange(300, dtype=np.int32),
        "gender": np.array("neutral"),
        "empty": np.zeros((0, 3)),
        "rate": np.array(30.0),
        "flags": rng.random((300, 2)) > 0.5,
        "hands": np.zeros((300, 90)),
    }


def test_npz_reads_back_exactly_and_passes_zipfile_checks(tmp_path) -> None:
    path = tmp_path / "x.npz"
    util.write_npz_compressed_atomic(path, **arrays())
    with np.load(path, allow_pickle=False) as data:
        assert data.files == list(arrays())
        for name, value in arrays().items():
            assert data[name].dtype == value.dtype
            np.testing.assert_array_equal(data[name], value)
    with zipfile.ZipFile(path) as archive:
        assert archive.testzip() is None  # every member's CRC checks out
        infos = archive.infolist()
    assert {i.compress_type for i in infos} == {zipfile.ZIP_DEFLATED}
    assert {i.date_time for i in infos} == {(1980, 1, 1, 0, 0, 0)}
    hands = next(i for i in infos if i.filename == "hands.npy")
    assert hands.compress_size < 0.05 * hands.file_size  # really deflated


def test_npz_bytes_depend_only_on_the_arrays(tmp_path) -> None:
    util.write_npz_compressed_atomic(tmp_path / "a.npz", **arrays())
    util.write_npz_compressed_atomic(tmp_path / "b.npz", **arrays())
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_archives_beyond_the_plain_zip_limits_go_to_zipfile(monkeypatch, tmp_path) -> None:
    """Past 4 GiB a zip needs ZIP64, which the hand-written archive leaves to zipfile (limit lowered here)."""
    monkeypatch.setattr(util, "_ZIP_LIMIT", 1000)
    path = tmp_path / "big.npz"
    util.write_npz_compressed_atomic(path, **arrays())
    with np.load(path, allow_pickle=False) as data:
        np.testing.assert_array_equal(data["poses"], arrays()["poses"])
    assert path.read_bytes() == util._zipfile_deflated({f"{k}.npy": _npy(v) for k, v in arrays().items()})


def _npy(value: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, value, allow_pickle=False)
    return buffer.getvalue()


@pytest.mark.parametrize("name", ["poses", "gender"])
def test_a_single_member_archive(tmp_path, name) -> None:
    path = tmp_path / "one.npz"
    util.write_npz_compressed_atomic(path, **{name: arrays()[name]})
    with np.load(path, allow_pickle=False) as data:
        np.testing.assert_array_equal(data[name], arrays()[name])


def test_abandoned_atomic_writes_are_removed_and_live_ones_kept(tmp_path) -> None:
    """A write killed mid-way leaves ``.<name>.<pid>-<random>.tmp``; only a dead process's file goes."""
    import os
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    (tmp_path / "sub").mkdir()
    abandoned = tmp_path / "sub" / f".stages.json.{dead_pid}-ab12_x9.tmp"
    live = tmp_path / f".crowd.parquet.{os.getpid()}-zz99.tmp"
    other = tmp_path / ".notes.tmp"
    for path in (abandoned, live, other):
        path.write_bytes(b"partial")
    util.write_bytes_atomic(tmp_path / "kept.json", b"{}")
    util.remove_abandoned_writes(tmp_path)
    assert not abandoned.exists()
    assert live.exists() and other.exists() and (tmp_path / "kept.json").read_bytes() == b"{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, other.name, "kept.json", "sub"])
