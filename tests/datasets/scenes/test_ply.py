"""Gaussian PLY: the real SuperSplat file, compressed and standard round trips, bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.lib.recfunctions import repack_fields
from plyfile import PlyData, PlyElement

from song.datasets.scenes._ply_kernel import pack_vertices
from song.datasets.scenes.ply import (
    CHUNK,
    MIN_SPAN,
    SH_C0,
    SQRT1_2,
    GaussianCloud,
    _part1by2,
    check_gaussian_ply,
    morton_order,
    pack_vertices_reference,
    read_gaussian_ply,
    write_compressed_ply,
    write_standard_ply,
)
from song.errors import FormatError
from tests.conftest import GUITAR, shared_file, splat_file

PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")


def _random_cloud(n: int, seed: int, sh: int = 0) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return GaussianCloud(
        means=rng.uniform(-5, 5, (n, 3)).astype(np.float32),
        quats=(q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
        log_scales=rng.uniform(-6, -1, (n, 3)).astype(np.float32),
        opacity_logits=rng.uniform(-4, 4, n).astype(np.float32),
        sh_dc=rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32),
        sh_rest=rng.uniform(-3.9, 3.9, (n, sh, 3)).astype(np.float32) if sh else None,
    )


def _take(cloud: GaussianCloud, index: np.ndarray) -> GaussianCloud:
    return GaussianCloud(*(None if a is None else a[index] for a in vars(cloud).values()))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 2 * np.degrees(np.arccos(np.clip(np.abs((a * b).sum(axis=1)), 0, 1)))


def test_real_supersplat_file() -> None:
    shared_file(GUITAR)
    assert check_gaussian_ply(GUITAR) == 90_854
    cloud = read_gaussian_ply(GUITAR)
    assert len(cloud) == 90_854 and PlyData.read(str(GUITAR))["chunk"].count == 355
    np.testing.assert_allclose(np.linalg.norm(cloud.quats, axis=1), 1.0, atol=1e-6)
    lo, hi = cloud.means.min(axis=0), cloud.means.max(axis=0)  # README: [-0.66, 0.82] x [-4.29, 0.09] x [-0.53, 0.92]
    assert (lo > [-0.7, -4.3, -0.6]).all() and (hi < [0.85, 0.1, 0.95]).all()
    assert (lo < [-0.6, -4.2, -0.5]).all() and (hi > [0.8, 0.05, 0.9]).all()
    alpha_bytes = np.asarray(PlyData.read(str(GUITAR))["vertex"]["packed_color"]) & 0xFF
    assert alpha_bytes.max() == 255
    assert np.isfinite(cloud.opacity_logits).all()  # byte 255 clamped before the logit
    assert cloud.opacity_logits.max() == pytest.approx(np.log((1 - 1e-6) / 1e-6), rel=1e-5)
    assert (0.5 + SH_C0 * cloud.sh_dc).max() > 1.0  # per-chunk colour ranges exceed [0, 1] (README)


def test_reencoding_the_supersplat_file_reproduces_its_words(tmp_path: Path) -> None:
    shared_file(GUITAR)
    """Our quantiser is SuperSplat's: decode → encode in file order gives the same chunks and words."""
    write_compressed_ply(tmp_path / "again.ply", read_gaussian_ply(GUITAR))
    theirs, ours = PlyData.read(str(GUITAR)), PlyData.read(str(tmp_path / "again.ply"))
    for name in theirs["chunk"].data.dtype.names:  # all 18 float ranges bit-exact
        np.testing.assert_array_equal(ours["chunk"][name], theirs["chunk"][name])
    for name in ("packed_position", "packed_scale", "packed_color"):
        np.testing.assert_array_equal(ours["vertex"][name], theirs["vertex"][name])
    a = np.asarray(theirs["vertex"]["packed_rotation"])
    b = np.asarray(ours["vertex"]["packed_rotation"])
    differ = a != b
    assert differ.mean() < 0.005  # 199 of 90,854: near-ties between the two largest components
    assert ((a[differ] >> 30) != (b[differ] >> 30)).all()  # only the choice of the dropped component
    back = read_gaussian_ply(tmp_path / "again.ply").quats[differ]
    assert _angle_deg(back, read_gaussian_ply(GUITAR).quats[differ]).max() < 0.3


def test_supersplat_file_is_in_our_morton_order() -> None:
    shared_file(GUITAR)
    cloud = read_gaussian_ply(GUITAR)
    p = cloud.means.astype(np.float64)
    cells = np.minimum(1023, (p - p.min(axis=0)) * 1024 / np.ptp(p, axis=0)).astype(np.uint32)
    code = _part1by2(cells[:, 0]) | (_part1by2(cells[:, 1]) << 1) | (_part1by2(cells[:, 2]) << 2)
    assert (np.diff(code.astype(np.int64)) >= 0).mean() > 0.98  # 99.1 %: off only by position quantisation
    order = morton_order(cloud.means)
    assert sorted(order.tolist()) == list(range(len(cloud)))
    assert (np.diff(code[order].astype(np.int64)) >= 0).all()
    assert _part1by2(np.array([0b1011], dtype=np.uint32))[0] == 0b1000001001  # bits spread three apart


def test_compressed_round_trip_within_quantisation(tmp_path: Path) -> None:
    n = 1000
    cloud = _take(_random_cloud(n, 0, sh=15), np.argsort(_random_cloud(n, 0).means[:, 0]))
    write_compressed_ply(tmp_path / "c.ply", cloud)
    back = read_gaussian_ply(tmp_path / "c.ply")
    bits = np.array([2047, 1023, 2047])
    colour, colour_back = 0.5 + SH_C0 * cloud.sh_dc, 0.5 + SH_C0 * back.sh_dc
    for i in range(0, n, 256):
        part = slice(i, i + 256)
        # position and log-scale: half a step of 11/10/11 bits of the chunk's range, per axis
        for ours, theirs in ((back.means, cloud.means), (back.log_scales, cloud.log_scales)):
            half_step = np.ptp(theirs[part], axis=0) / bits / 2
            assert (np.abs(ours[part] - theirs[part]) <= half_step + 1e-6).all()
        # colour 0.5 + C0·f_dc: half a step of 8 bits of the chunk's colour range
        half_step = np.ptp(colour[part], axis=0) / 255 / 2
        assert (np.abs(colour_back[part] - colour[part]) <= half_step + 1e-6).all()
    # rotation, 10-bit smallest three: the three stored components within half a step (√2/1023/2),
    # the rebuilt largest one within 3 half steps (it is ≥ 1/2), so the angle stays under 0.25°
    q = cloud.quats.astype(np.float64)
    largest = np.argmax(np.abs(q), axis=1)
    sign = np.sign(q[np.arange(n), largest])[:, None]
    err = np.abs(back.quats * sign - q)
    stored = np.ones_like(err, dtype=bool)
    stored[np.arange(n), largest] = False
    half = np.sqrt(2) / 1023 / 2
    assert err[stored].max() <= half + 1e-6 and err[~stored].max() <= 3 * half
    assert _angle_deg(back.quats, cloud.quats).max() < 0.25
    np.testing.assert_allclose(np.linalg.norm(back.quats, axis=1), 1.0, atol=1e-6)
    sigmoid = lambda x: 1 / (1 + np.exp(-x.astype(np.float64)))  # noqa: E731
    assert np.abs(sigmoid(back.opacity_logits) - sigmoid(cloud.opacity_logits)).max() <= 0.5 / 255 + 1e-6
    assert np.abs(back.sh_rest - cloud.sh_rest).max() <= 4 / 256 + 1e-6  # 256 bins over [-4, 4], bin centres
    write_compressed_ply(tmp_path / "again.ply", cloud)
    assert (tmp_path / "again.ply").read_bytes() == (tmp_path / "c.ply").read_bytes()


def test_compiled_packing_equals_its_numpy_twin() -> None:
    rng = np.random.default_rng(3)
    for n in (1, CHUNK - 1, 3 * CHUNK + 17):
        chunks = (n + CHUNK - 1) // CHUNK
        groups = []
        for spread in (5.0, 3.0, 1.0):
            values = rng.uniform(-spread, spread, (n, 3))
            lo = np.sort(rng.uniform(-spread, spread, (chunks, 2, 3)), axis=1)
            lo, hi = lo[:, 0].astype(np.float32).astype(np.float64), lo[:, 1].astype(np.float32).astype(np.float64)
            hi[0, 0] = lo[0, 0] + MIN_SPAN / 2  # a range too narrow to store
            values[: min(n, 3), 1] = lo[0, 1]  # on the bounds exactly
            values[-1, 2] = hi[-1, 2]
            groups += [values, lo, hi]
        quats = rng.normal(size=(n, 4))
        quats[0] = [0.5, -0.5, 0.5, -0.5]  # equal magnitudes: the first is the largest
        quats[-1] = [0.1, -0.9, 0.3, 0.2]  # a negative largest
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        opacity = rng.uniform(0, 1, n)
        opacity[0] = 0.5 / 255  # halfway between two codes
        args = (*groups, opacity, quats, CHUNK, MIN_SPAN, SQRT1_2)
        for ours, twin in zip(pack_vertices(*args), pack_vertices_reference(*args), strict=True):
            np.testing.assert_array_equal(ours, twin)


def test_morton_write_is_a_permutation(tmp_path: Path) -> None:
    cloud = _random_cloud(700, 3, sh=3)
    write_compressed_ply(tmp_path / "m.ply", cloud, morton=True)
    back = read_gaussian_ply(tmp_path / "m.ply")
    order = morton_order(cloud.means)
    assert np.abs(back.means - cloud.means[order]).max() < 10 / 2047  # chunk ranges ≤ 10 m
    assert back.sh_rest.shape == (700, 3, 3) and len(PlyData.read(str(tmp_path / "m.ply"))["sh"].properties) == 9
    write_compressed_ply(tmp_path / "m2.ply", _take(cloud, np.arange(700)[::-1]), morton=True)
    # a permuted input gives the same splats in the same spatial order (ties aside)
    assert np.abs(read_gaussian_ply(tmp_path / "m2.ply").means - back.means).max() < 10 / 2047


def test_twelve_property_chunks(tmp_path: Path) -> None:
    """The older variant: no per-chunk colour range; colour bytes are absolute in [0, 1]."""
    cloud = _random_cloud(300, 4)
    cloud.sh_dc = ((np.random.default_rng(4).uniform(0, 1, (300, 3)) - 0.5) / SH_C0).astype(np.float32)
    write_compressed_ply(tmp_path / "18.ply", cloud)
    ply = PlyData.read(str(tmp_path / "18.ply"))
    names = [p.name for p in ply["chunk"].properties][:12]
    chunk = np.empty(ply["chunk"].count, dtype=[(k, "<f4") for k in names])
    for k in names:
        chunk[k] = ply["chunk"][k]
    colour = np.clip(np.round((0.5 + SH_C0 * cloud.sh_dc.astype(np.float64)) * 255), 0, 255).astype(np.uint32)
    vertex = np.array(ply["vertex"].data)
    vertex["packed_color"] = (
        (colour[:, 0] << 24) | (colour[:, 1] << 16) | (colour[:, 2] << 8) | (vertex["packed_color"] & 0xFF)
    )
    elements = [PlyElement.describe(chunk, "chunk"), PlyElement.describe(vertex, "vertex")]
    PlyData(elements, text=False, byte_order="<").write(str(tmp_path / "12.ply"))
    back = read_gaussian_ply(tmp_path / "12.ply")
    err = np.abs(SH_C0 * (back.sh_dc - cloud.sh_dc))
    assert err.max() <= 0.5 / 255 + 1e-6
    np.testing.assert_array_equal(back.means, read_gaussian_ply(tmp_path / "18.ply").means)


def test_standard_round_trip_exact_and_plain_reader(tmp_path: Path) -> None:
    cloud = _random_cloud(300, 1, sh=15)
    write_standard_ply(tmp_path / "s.ply", cloud)
    back = read_gaussian_ply(tmp_path / "s.ply")
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh_dc", "sh_rest"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cloud, name))
    vertex = PlyData.read(str(tmp_path / "s.ply"))["vertex"]  # plain plyfile, no code of ours
    names = [p.name for p in vertex.properties]
    assert names[:9] == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    assert names[9:54] == [f"f_rest_{i}" for i in range(45)]
    assert names[54:] == ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    assert all(
        p.val_dtype in ("f4", "<f4", "float32") or np.dtype(p.val_dtype) == np.float32 for p in vertex.properties
    )
    np.testing.assert_array_equal(vertex["f_rest_15"], cloud.sh_rest[:, 0, 1])  # channel-major: green, first coeff
    np.testing.assert_array_equal(vertex["rot_0"], cloud.quats[:, 0])
    write_standard_ply(tmp_path / "again.ply", cloud)
    assert (tmp_path / "again.ply").read_bytes() == (tmp_path / "s.ply").read_bytes()


def _rewrite(src: Path, dst: Path, edit) -> None:
    ply = PlyData.read(str(src))
    arrays = {e.name: np.array(e.data) for e in ply.elements}
    edit(arrays)
    PlyData([PlyElement.describe(a, k) for k, a in arrays.items()], text=False).write(str(dst))


def _retype(arrays: dict) -> None:
    v = arrays["vertex"]
    arrays["vertex"] = v.astype([(k, "<f4" if k == "packed_position" else "<u4") for k in v.dtype.names])


DAMAGE = {
    "truncated": ("", "vertex"),
    "garbage": ("", "header"),
    "missing": ("", "missing"),
    "no_vertex": ("", "vertex"),
    "packed_as_float": (_retype, "vertex.packed_position"),
    "one_chunk_short": (lambda a: a.update(chunk=a["chunk"][:-1]), "chunk"),
    "no_scale_range": (
        lambda a: a.update(chunk=repack_fields(a["chunk"][["min_x", "min_y", "min_z", "max_x"]])),
        "chunk.max_y",
    ),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_bad_ply_names_file_and_element(tmp_path: Path, damage: str) -> None:
    path = tmp_path / "bad.ply"
    edit, where = DAMAGE[damage]
    if damage == "truncated":
        data = splat_file().read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"not a ply at all\x00\x01")
    elif damage == "no_vertex":
        path.write_bytes(b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    elif edit:
        _rewrite(splat_file(), path, edit)
    for reader in (read_gaussian_ply, check_gaussian_ply):
        with pytest.raises(FormatError) as info:
            reader(path)
        message = str(info.value)
        assert str(path) in message and where in message and "\n" not in message, message


def test_scenes_are_stored_upright_for_3dgs_viewers_and_read_back_in_our_frame(tmp_path: Path) -> None:
    from song.datasets.scenes.ply import VIEWER_FRAME_COMMENT

    cloud = _random_cloud(512, 3)
    cloud.means[:, 2] = np.abs(cloud.means[:, 2]) / 2  # a room: z from the floor (0) to 2.5 m
    write_compressed_ply(tmp_path / "s.ply", cloud, viewer_frame=True)
    ply = PlyData.read(str(tmp_path / "s.ply"))
    assert VIEWER_FRAME_COMMENT in ply.comments
    chunk = ply["chunk"]
    # in the file the height runs along -y, as in a COLMAP capture that SuperSplat shows upright
    assert chunk["max_y"].max() <= 1e-6 and chunk["min_y"].min() == pytest.approx(-cloud.means[:, 2].max(), abs=1e-3)
    assert chunk["max_z"].max() == pytest.approx(cloud.means[:, 1].max(), abs=1e-3)  # our +y is the file's +z
    back = read_gaussian_ply(tmp_path / "s.ply")
    plain = tmp_path / "p.ply"
    write_compressed_ply(plain, cloud)
    reference = read_gaussian_ply(plain)  # the same quantisation in our own frame
    assert np.abs(back.means - cloud.means).max() <= np.abs(reference.means - cloud.means).max() * 1.5 + 1e-4
    assert _angle_deg(back.quats, cloud.quats).max() < 0.25  # the turn was undone on the rotations too
    with pytest.raises(ValueError, match="SH degree 0"):
        write_compressed_ply(tmp_path / "sh.ply", _random_cloud(10, 1, sh=3), viewer_frame=True)


def test_compiled_viewer_turn_matches_quat_mul() -> None:
    """The compiled quarter turn of the splats' rotations equals ``quat_mul`` in float64, rounded to float32."""
    from song.datasets.scenes._ply_kernel import turn_quats
    from song.datasets.scenes.ply import TURN_TO_VIEWER
    from song.geometry.rotations import quat_conj, quat_mul

    rng = np.random.default_rng(4)
    q = rng.normal(size=(5000, 4)).astype(np.float32)
    for turn in (TURN_TO_VIEWER, quat_conj(TURN_TO_VIEWER)):
        want = quat_mul(np.broadcast_to(turn, q.shape), q.astype(np.float64)).astype(np.float32)
        np.testing.assert_array_equal(turn_quats(np.asarray(turn, dtype=np.float64), q), want)
