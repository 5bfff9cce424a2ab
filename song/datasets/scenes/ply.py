"""Gaussian PLY: standard 3DGS and PlayCanvas/SuperSplat compressed (DESIGN §4.2).

Standard 3DGS PLY: one ``vertex`` element with float properties x y z, nx ny nz, f_dc_0..2,
f_rest_*, opacity (logit), scale_0..2 (log), rot_0..3 (w x y z).

Compressed PLY (SuperSplat): a ``chunk`` element (one row per 256 splats, 12 float properties
min/max of position and of log-scale, or 18 with min/max colour too) and a ``vertex`` element of four
uint32 words per splat: position and log-scale packed 11-10-11 bits as fractions of the chunk's
range, the rotation as "smallest three" (2 bits: index of the largest of rot_0..rot_3, then the other
three in order, 10 bits each, in [−1/√2, 1/√2]), and colour+opacity 8-8-8-8 (colour = 0.5 + C0·f_dc,
opacity = sigmoid(logit)). An optional ``sh`` element holds f_rest as uint8: f = (v/255 − 0.5)·8.
``plyfile`` reads and writes the container; the bit packing is ours, vectorised.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song.errors import FormatError
from song.util import write_bytes_atomic

SH_C0 = 0.28209479177387814
CHUNK = 256
CHUNK_POS = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z")
CHUNK_SCALE = ("min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z")
CHUNK_COLOR = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
SQRT1_2 = float(np.sqrt(0.5))


@dataclass
class GaussianCloud:
    """A set of 3D Gaussians.

    Attributes:
        means: (N, 3) float32, metres.
        quats: (N, 4) float32, unit quaternions (w, x, y, z).
        log_scales: (N, 3) float32, natural log of the per-axis standard deviations (metres).
        opacity_logits: (N,) float32, logit of opacity.
        sh_dc: (N, 3) float32, degree-0 SH coefficients (colour = 0.5 + C0 · sh_dc, C0 = 0.28209479).
        sh_rest: (N, K, 3) float32 higher-order SH coefficients, or None.
    """

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh_dc: np.ndarray
    sh_rest: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.means.shape[0])


def _open(path: Path):
    from plyfile import PlyData, PlyElementParseError, PlyHeaderParseError

    if not path.is_file():
        raise FormatError(path, "", "file is missing")
    try:
        return PlyData.read(str(path))
    except PlyElementParseError as exc:
        raise FormatError(
            path, exc.element.name if exc.element else "body", f"truncated or malformed data ({exc.message})"
        ) from exc
    except (PlyHeaderParseError, ValueError, OSError, EOFError, IndexError) as exc:
        raise FormatError(path, "header", f"not a readable PLY ({exc})") from exc


def _column(element, name: str, path: Path) -> np.ndarray:
    try:
        return np.asarray(element[name])
    except (ValueError, KeyError) as exc:
        raise FormatError(path, f"{element.name}.{name}", "property is missing") from exc


def read_gaussian_ply(path: str | Path) -> GaussianCloud:
    """Read either PLY form (compressed when a ``chunk`` element with packed vertices is present)."""
    path = Path(path)
    ply = _open(path)
    names = [element.name for element in ply.elements]
    if "vertex" not in names:
        raise FormatError(path, "vertex", "element is missing")
    try:
        if "chunk" in names:
            return _read_compressed(ply, path)
        return _read_standard(ply["vertex"], path)
    except (ValueError, IndexError) as exc:  # truncated bodies surface here in plyfile's lazy reads
        raise FormatError(path, "vertex", f"truncated or malformed data ({exc})") from exc


def _read_standard(vertex, path: Path) -> GaussianCloud:
    col = lambda name: _column(vertex, name, path).astype(np.float32)  # noqa: E731
    rest_names = sorted(
        (p.name for p in vertex.properties if p.name.startswith("f_rest_")), key=lambda n: int(n.split("_")[-1])
    )
    rest = None
    if rest_names:
        flat = np.stack([col(n) for n in rest_names], axis=1)
        rest = flat.reshape(len(flat), 3, -1).transpose(0, 2, 1).copy()  # 3DGS stores channel-major
    return GaussianCloud(
        means=np.stack([col("x"), col("y"), col("z")], axis=1),
        quats=np.stack([col(f"rot_{i}") for i in range(4)], axis=1),
        log_scales=np.stack([col(f"scale_{i}") for i in range(3)], axis=1),
        opacity_logits=col("opacity"),
        sh_dc=np.stack([col(f"f_dc_{i}") for i in range(3)], axis=1),
        sh_rest=rest,
    )


def _unorm(value: np.ndarray, shift: int, bits: int) -> np.ndarray:
    return ((value >> np.uint32(shift)) & np.uint32((1 << bits) - 1)).astype(np.float64) / ((1 << bits) - 1)


def _unpack_111011(value: np.ndarray) -> np.ndarray:
    return np.stack([_unorm(value, 21, 11), _unorm(value, 11, 10), _unorm(value, 0, 11)], axis=1)


def _read_compressed(ply, path: Path) -> GaussianCloud:
    chunk, vertex = ply["chunk"], ply["vertex"]
    n = vertex.count
    if chunk.count != (n + CHUNK - 1) // CHUNK:
        raise FormatError(path, "chunk", f"{chunk.count} chunks cannot hold {n} splats (256 per chunk)")
    packed = {name: _column(vertex, name, path).astype(np.uint32) for name in PACKED}
    index = np.arange(n) // CHUNK
    c = {name: _column(chunk, name, path).astype(np.float64)[index] for name in CHUNK_POS + CHUNK_SCALE}
    lo = np.stack([c[k] for k in CHUNK_POS[:3]], axis=1)
    hi = np.stack([c[k] for k in CHUNK_POS[3:]], axis=1)
    means = lo + (hi - lo) * _unpack_111011(packed["packed_position"])
    slo = np.stack([c[k] for k in CHUNK_SCALE[:3]], axis=1)
    shi = np.stack([c[k] for k in CHUNK_SCALE[3:]], axis=1)
    log_scales = slo + (shi - slo) * _unpack_111011(packed["packed_scale"])
    word = packed["packed_color"]
    rgba = np.stack([_unorm(word, s, 8) for s in (24, 16, 8, 0)], axis=1)
    colour = rgba[:, :3]
    if set(CHUNK_COLOR) <= {prop.name for prop in chunk.properties}:  # the 18-property chunk variant
        clo = np.stack([_column(chunk, k, path)[index] for k in CHUNK_COLOR[:3]], axis=1)
        chi = np.stack([_column(chunk, k, path)[index] for k in CHUNK_COLOR[3:]], axis=1)
        colour = clo + (chi - clo) * colour
    alpha = np.clip(rgba[:, 3], 1e-6, 1 - 1e-6)  # byte 255 → 1.0 would be an infinite logit
    quats = _unpack_rotation(packed["packed_rotation"])
    rest = None
    if "sh" in [e.name for e in ply.elements]:
        sh = ply["sh"]
        names = sorted((p.name for p in sh.properties), key=lambda s: int(s.split("_")[-1]))
        flat = np.stack([np.asarray(sh[k], dtype=np.float64) for k in names], axis=1)
        flat = (flat / 255.0 - 0.5) * 8.0
        rest = flat.reshape(n, 3, -1).transpose(0, 2, 1).astype(np.float32)
    return GaussianCloud(
        means=means.astype(np.float32),
        quats=quats.astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        opacity_logits=np.log(alpha / (1 - alpha)).astype(np.float32),
        sh_dc=((colour - 0.5) / SH_C0).astype(np.float32),
        sh_rest=rest,
    )


def _unpack_rotation(word: np.ndarray) -> np.ndarray:
    norm = 1.0 / (np.sqrt(2.0) * 0.5)
    abc = np.stack([_unorm(word, 20, 10), _unorm(word, 10, 10), _unorm(word, 0, 10)], axis=1)
    abc = (abc - 0.5) * norm
    largest = (word >> np.uint32(30)).astype(np.int64)
    m = np.sqrt(np.clip(1.0 - (abc**2).sum(axis=1), 0.0, None))
    out = np.empty((len(word), 4))
    for k in range(4):
        rows = largest == k
        others = [i for i in range(4) if i != k]
        out[np.ix_(rows, others)] = abc[rows]
        out[rows, k] = m[rows]
    return out


def _pack_rotation(quats: np.ndarray) -> np.ndarray:
    q = quats / np.linalg.norm(quats, axis=1, keepdims=True)
    largest = np.argmax(np.abs(q), axis=1)
    q = q * np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)[:, None]  # q ≡ −q: make it positive
    word = largest.astype(np.uint32) << np.uint32(30)
    for k in range(4):
        rows = largest == k
        others = q[rows][:, [i for i in range(4) if i != k]]
        t = np.clip(np.round((others * SQRT1_2 + 0.5) * 1023), 0, 1023).astype(np.uint32)
        word[rows] |= (t[:, 0] << np.uint32(20)) | (t[:, 1] << np.uint32(10)) | t[:, 2]
    return word


def _pack_111011(t: np.ndarray) -> np.ndarray:
    x = np.clip(np.round(t[:, 0] * 2047), 0, 2047).astype(np.uint32)
    y = np.clip(np.round(t[:, 1] * 1023), 0, 1023).astype(np.uint32)
    z = np.clip(np.round(t[:, 2] * 2047), 0, 2047).astype(np.uint32)
    return (x << np.uint32(21)) | (y << np.uint32(11)) | z


def _chunk_ranges(values: np.ndarray, n_chunks: int) -> tuple[np.ndarray, np.ndarray]:
    pad = n_chunks * CHUNK - len(values)
    padded = np.concatenate([values, np.repeat(values[-1:], pad, axis=0)]).reshape(n_chunks, CHUNK, -1)
    return padded.min(axis=1), padded.max(axis=1)


def _fraction(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    span = np.where(hi - lo > 0, hi - lo, 1.0)
    return (values - lo) / span


def _ply_bytes(elements: list) -> bytes:
    from plyfile import PlyData

    buffer = io.BytesIO()
    PlyData(elements, text=False, byte_order="<").write(buffer)
    return buffer.getvalue()


def write_standard_ply(path: str | Path, cloud: GaussianCloud) -> None:
    """Write a standard 3DGS PLY (binary little-endian, float32), readable by any splat viewer."""
    from plyfile import PlyElement

    n = len(cloud)
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    columns = [cloud.means[:, 0], cloud.means[:, 1], cloud.means[:, 2], *np.zeros((3, n)), *cloud.sh_dc.T]
    if cloud.sh_rest is not None:
        rest = cloud.sh_rest.transpose(0, 2, 1).reshape(n, -1)  # channel-major as 3DGS writes it
        names += [f"f_rest_{i}" for i in range(rest.shape[1])]
        columns += list(rest.T)
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    columns += [cloud.opacity_logits, *cloud.log_scales.T, *cloud.quats.T]
    data = np.empty(n, dtype=[(name, "<f4") for name in names])
    for name, column in zip(names, columns, strict=True):
        data[name] = column
    write_bytes_atomic(path, _ply_bytes([PlyElement.describe(data, "vertex")]))


def write_compressed_ply(path: str | Path, cloud: GaussianCloud) -> None:
    """Write the SuperSplat compressed PLY (18-property chunks, plus ``sh`` when present).

    Splats are written in the given order (callers sort spatially, e.g. by Morton code, for tight
    chunks); the bytes depend only on the cloud.
    """
    from plyfile import PlyElement

    n = len(cloud)
    if n == 0:
        raise ValueError("cannot write an empty Gaussian cloud")
    n_chunks = (n + CHUNK - 1) // CHUNK
    index = np.arange(n) // CHUNK
    means = cloud.means.astype(np.float64)
    scales = cloud.log_scales.astype(np.float64)
    colour = 0.5 + SH_C0 * cloud.sh_dc.astype(np.float64)
    plo, phi = _chunk_ranges(means, n_chunks)
    slo, shi = _chunk_ranges(scales, n_chunks)
    clo, chi = _chunk_ranges(colour, n_chunks)
    chunk = np.empty(n_chunks, dtype=[(name, "<f4") for name in CHUNK_POS + CHUNK_SCALE + CHUNK_COLOR])
    for k, name in enumerate(CHUNK_POS):
        chunk[name] = (plo if k < 3 else phi)[:, k % 3]
    for k, name in enumerate(CHUNK_SCALE):
        chunk[name] = (slo if k < 3 else shi)[:, k % 3]
    for k, name in enumerate(CHUNK_COLOR):
        chunk[name] = (clo if k < 3 else chi)[:, k % 3]
    # quantise against the float32 ranges actually stored, so decoding sees the same bounds
    as_stored = lambda a, b: (chunk[a].astype(np.float64)[index], chunk[b].astype(np.float64)[index])  # noqa: E731
    lo_p = np.stack([as_stored(CHUNK_POS[i], CHUNK_POS[i + 3])[0] for i in range(3)], axis=1)
    hi_p = np.stack([as_stored(CHUNK_POS[i], CHUNK_POS[i + 3])[1] for i in range(3)], axis=1)
    lo_s = np.stack([as_stored(CHUNK_SCALE[i], CHUNK_SCALE[i + 3])[0] for i in range(3)], axis=1)
    hi_s = np.stack([as_stored(CHUNK_SCALE[i], CHUNK_SCALE[i + 3])[1] for i in range(3)], axis=1)
    lo_c = np.stack([as_stored(CHUNK_COLOR[i], CHUNK_COLOR[i + 3])[0] for i in range(3)], axis=1)
    hi_c = np.stack([as_stored(CHUNK_COLOR[i], CHUNK_COLOR[i + 3])[1] for i in range(3)], axis=1)
    opacity = 1.0 / (1.0 + np.exp(-cloud.opacity_logits.astype(np.float64)))
    rgba = np.column_stack([np.clip(_fraction(colour, lo_c, hi_c), 0, 1), opacity])
    bytes_ = np.clip(np.round(rgba * 255), 0, 255).astype(np.uint32)
    vertex = np.empty(n, dtype=[(name, "<u4") for name in PACKED])
    vertex["packed_position"] = _pack_111011(np.clip(_fraction(means, lo_p, hi_p), 0, 1))
    vertex["packed_rotation"] = _pack_rotation(cloud.quats.astype(np.float64))
    vertex["packed_scale"] = _pack_111011(np.clip(_fraction(scales, lo_s, hi_s), 0, 1))
    vertex["packed_color"] = (bytes_[:, 0] << 24) | (bytes_[:, 1] << 16) | (bytes_[:, 2] << 8) | bytes_[:, 3]
    elements = [PlyElement.describe(chunk, "chunk"), PlyElement.describe(vertex, "vertex")]
    if cloud.sh_rest is not None:
        flat = cloud.sh_rest.transpose(0, 2, 1).reshape(n, -1).astype(np.float64)
        sh = np.empty(n, dtype=[(f"f_rest_{i}", "u1") for i in range(flat.shape[1])])
        q = np.clip(np.round((flat / 8.0 + 0.5) * 255), 0, 255).astype(np.uint8)
        for i in range(flat.shape[1]):
            sh[f"f_rest_{i}"] = q[:, i]
        elements.append(PlyElement.describe(sh, "sh"))
    write_bytes_atomic(path, _ply_bytes(elements))
