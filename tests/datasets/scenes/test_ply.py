"""Gaussian PLY: the real SuperSplat file, compressed and standard round trips, bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from plyfile import PlyData

from song.datasets.scenes.ply import SH_C0, GaussianCloud, read_gaussian_ply, write_compressed_ply, write_standard_ply
from song.errors import FormatError

GUITAR = Path(__file__).resolve().parents[2] / "data" / "playcanvas_splat" / "guitar.compressed.ply"


def _random_cloud(n: int, seed: int, sh: bool = False) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return GaussianCloud(
        means=rng.uniform(-5, 5, (n, 3)).astype(np.float32),
        quats=(q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
        log_scales=rng.uniform(-6, -1, (n, 3)).astype(np.float32),
        opacity_logits=rng.uniform(-4, 4, n).astype(np.float32),
        sh_dc=rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32),
        sh_rest=rng.uniform(-1, 1, (n, 15, 3)).astype(np.float32) if sh else None,
    )


def test_real_supersplat_file() -> None:
    cloud = read_gaussian_ply(GUITAR)
    assert len(cloud) == 90_854 and PlyData.read(str(GUITAR))["chunk"].count == 355
    np.testing.assert_allclose(np.linalg.norm(cloud.quats, axis=1), 1.0, atol=1e-6)
    lo, hi = cloud.means.min(axis=0), cloud.means.max(axis=0)
    assert (lo > [-0.7, -4.3, -0.6]).all() and (hi < [0.85, 0.1, 0.95]).all()
    assert np.isfinite(cloud.opacity_logits).all()  # byte 255 clamped before the logit
    assert (0.5 + SH_C0 * cloud.sh_dc).max() > 1.0  # per-chunk colour ranges exceed [0, 1] (README)


def test_compressed_round_trip_within_quantisation(tmp_path: Path) -> None:
    cloud = _random_cloud(1000, 0, sh=True)
    order = np.argsort(cloud.means[:, 0])  # spatially sorted, as SuperSplat writes
    cloud = GaussianCloud(*(a[order] if a is not None else None for a in vars(cloud).values()))
    write_compressed_ply(tmp_path / "c.ply", cloud)
    back = read_gaussian_ply(tmp_path / "c.ply")
    # 11/10/11 bits of each chunk's range: half a step per axis
    per_chunk = np.array([np.ptp(cloud.means[i : i + 256], axis=0) for i in range(0, 1000, 256)])
    steps = per_chunk / np.array([2047, 1023, 2047])
    for k, i in enumerate(range(0, 1000, 256)):
        err = np.abs(back.means[i : i + 256] - cloud.means[i : i + 256])
        assert (err <= steps[k] / 2 + 1e-5).all()
    angle = 2 * np.degrees(np.arccos(np.clip(np.abs((back.quats * cloud.quats).sum(axis=1)), 0, 1)))
    assert angle.max() < 0.25  # 10-bit smallest-three: ≈ 0.08° typical
    assert np.abs(back.log_scales - cloud.log_scales).max() < 5.0 / 1023
    colour_err = np.abs((back.sh_dc - cloud.sh_dc) * SH_C0)
    assert colour_err.max() < 1.0 / 255 * (3.0 * SH_C0) + 1e-6  # 8 bits of the chunk colour range
    opacity = lambda x: 1 / (1 + np.exp(-x))  # noqa: E731
    assert np.abs(opacity(back.opacity_logits) - opacity(cloud.opacity_logits)).max() <= 0.5 / 255 + 1e-6
    assert np.abs(back.sh_rest - cloud.sh_rest).max() <= 8 / 255 / 2 + 1e-6
    write_compressed_ply(tmp_path / "again.ply", cloud)
    assert (tmp_path / "again.ply").read_bytes() == (tmp_path / "c.ply").read_bytes()


def test_standard_round_trip_exact_and_plain_reader(tmp_path: Path) -> None:
    cloud = _random_cloud(300, 1, sh=True)
    write_standard_ply(tmp_path / "s.ply", cloud)
    back = read_gaussian_ply(tmp_path / "s.ply")
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh_dc", "sh_rest"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cloud, name))
    vertex = PlyData.read(str(tmp_path / "s.ply"))["vertex"]
    names = [p.name for p in vertex.properties]
    assert names[:9] == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    assert names[-8:] == ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    assert "f_rest_44" in names


@pytest.mark.parametrize("damage", ["truncated", "garbage", "missing", "no_vertex"])
def test_bad_ply_names_file(tmp_path: Path, damage: str) -> None:
    path = tmp_path / "bad.ply"
    if damage == "truncated":
        data = GUITAR.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"not a ply at all\x00\x01")
    elif damage == "no_vertex":
        path.write_bytes(b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    with pytest.raises(FormatError) as info:
        read_gaussian_ply(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
