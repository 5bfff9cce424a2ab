"""Gaussian PLY: standard 3DGS and PlayCanvas/SuperSplat compressed.

Standard 3DGS PLY: one ``vertex`` element with float properties x y z, nx ny nz, f_dc_0..2,
f_rest_*, opacity (logit), scale_0..2 (log), rot_0..3 (w x y z).

Compressed PLY (SuperSplat): a ``chunk`` element (one row per 256 splats, 12 float properties
min/max of position and of log-scale, or 18 with min/max colour too) and a ``vertex`` element of four
uint32 words per splat: position and log-scale packed 11-10-11 bits as fractions of the chunk's
range, the rotation as "smallest three" (2 bits: index of the largest of rot_0..rot_3, then the other
three in order, 10 bits each, in [−1/√2, 1/√2]), and colour+opacity 8-8-8-8 (colour = 0.5 + C0·f_dc,
opacity = sigmoid(logit)). An optional ``sh`` element holds f_rest as uint8 (9, 24 or 45 of them):
encoded trunc((f/8 + 0.5)·256), decoded f = (n − 0.5)·8 with n = (v + 0.5)/256 (0 → 0, 255 → 1).
Quantisation follows SuperSplat/splat-transform: a fraction t of a chunk range becomes
floor(t·(2^bits − 1) + 0.5); a range narrower than 1e-5 stores 0; log-scale ranges are clamped to
[−20, 20]; the last chunk's ranges include copies of its last splat (padding to 256).

Orientation: SONG's frame is Z up. 3DGS viewers (SuperSplat, PlayCanvas, the web viewers) show a
capture upright when its up is −Y, the frame COLMAP-trained captures come in (the PlayCanvas ``biker``
sample, which SuperSplat shows standing, has its up along −Y). ``write_compressed_ply(...,
viewer_frame=True)`` stores positions and rotations turned +90° about X (file = (x, −z, y)) and says
so in the header comment :data:`VIEWER_FRAME_COMMENT`; :func:`read_gaussian_ply` undoes the turn when
it finds that comment, so SONG reads its own frame back and files without it are read as they are.
The scenes SONG synthesises are written this way (their colours are SH degree 0, which a rotation
leaves unchanged).

Order: :func:`write_compressed_ply` keeps the cloud's order by default, so splat ``i`` read back is
splat ``i`` written (callers sort spatially for tight chunks); ``morton=True`` sorts as SuperSplat
does (10-bit Morton code over the bounding box, buckets of more than 256 equal codes re-sorted within
their own box). ``plyfile`` reads and writes the container; the bit packing is ours, vectorised.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song.datasets.limits import limits, over
from song.datasets.scenes._ply_kernel import pack_vertices
from song.errors import FormatError
from song.util import write_bytes_atomic

SH_C0 = 0.28209479177387814
CHUNK = 256
CHUNK_POS = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z")
CHUNK_SCALE = ("min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z")
CHUNK_COLOR = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
SQRT1_2 = float(np.sqrt(0.5))
SCALE_LIMIT = 20.0  # SuperSplat clamps log-scale chunk ranges (some files hold ±inf)
MIN_SPAN = 1e-5  # a chunk range narrower than this stores fraction 0
SH_COUNTS = (9, 24, 45)  # f_rest values per splat for SH degree 1, 2, 3
OPACITY_EPS = 1e-6  # opacity byte 0/255 decodes to [eps, 1 − eps] so the logit stays finite
VIEWER_FRAME_COMMENT = "song-frame: y-down for 3DGS viewers; SONG's z-up frame is this turned -90 deg about x"
TURN_TO_VIEWER = np.array([np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0])  # +90° about x (w, x, y, z)


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


PLY_TYPES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
             "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}  # fmt: skip
MAX_HEADER_BYTES = 65_536


def _check_header(path: Path) -> None:
    """Refuse, before plyfile reads anything, a header whose declared body cannot be in the file.

    Lists (never in a Gaussian PLY; a list of 10⁹ rows makes plyfile loop row by row), element counts
    above ``max_splats`` and binary bodies larger than the file are refused with one line.
    """
    with path.open("rb") as handle:
        head = handle.read(MAX_HEADER_BYTES)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise FormatError(
            path, "header", f"not a readable PLY (no 'ply' … 'end_header' in its first {MAX_HEADER_BYTES} bytes)"
        )
    body = path.stat().st_size - (head.index(b"\n", end) + 1 if b"\n" in head[end:] else len(head))
    binary, needed, element, short = False, 0, None, None
    for line in head[:end].decode("ascii", errors="replace").splitlines():
        words = line.split()
        if words[:1] == ["format"]:
            binary = len(words) > 1 and words[1].startswith("binary")
        elif words[:1] == ["element"] and len(words) == 3 and words[2].isdigit():
            element = (words[1], int(words[2]))
            if element[1] > limits().max_splats:
                raise over(path, words[1], "element count", element[1], "max_splats")
        elif words[:1] == ["property"] and element is not None:
            if words[1:2] == ["list"]:
                name = words[-1] if len(words) > 4 else "?"
                raise FormatError(path, f"{element[0]}.{name}", "list properties are not part of a Gaussian PLY")
            needed += element[1] * PLY_TYPES.get(words[1] if len(words) > 1 else "", 0)
            if short is None and needed > body:
                short = element[0]  # the first element whose data cannot be in the file
    if binary and short is not None:
        raise FormatError(
            path, short, f"truncated: the header declares {needed:,} bytes of data, the file holds {max(body, 0):,}"
        )


def _open(path: Path):
    from plyfile import PlyData, PlyElementParseError, PlyHeaderParseError

    if not path.is_file():
        raise FormatError(path, "", "file is missing")
    _check_header(path)
    try:
        return PlyData.read(str(path))  # memory-mapped: the header is parsed and the body size checked
    except PlyElementParseError as exc:
        where = exc.element.name if exc.element else "body"
        if exc.prop is not None:
            where += f".{exc.prop.name}"
        row = f" at row {exc.row}" if exc.row is not None else ""
        raise FormatError(path, where, f"truncated or malformed data{row} ({exc.message})") from exc
    except (PlyHeaderParseError, ValueError, OSError, EOFError, IndexError) as exc:
        raise FormatError(path, "header", f"not a readable PLY ({' '.join(str(exc).split())})") from exc


def _column(element, name: str, path: Path) -> np.ndarray:
    try:
        return np.asarray(element[name])
    except (ValueError, KeyError) as exc:
        raise FormatError(path, f"{element.name}.{name}", "property is missing") from exc


def _require(element, names: tuple[str, ...], kinds: str, path: Path) -> None:
    """Each of ``names`` is a scalar property of ``element`` whose numpy kind/size is in ``kinds``."""
    props = {p.name: p for p in element.properties}
    for name in names:
        prop = props.get(name)
        if prop is None:
            raise FormatError(path, f"{element.name}.{name}", "property is missing")
        dtype = np.dtype(getattr(prop, "val_dtype", "O"))
        if f"{dtype.kind}{dtype.itemsize}" not in kinds.split():
            want = np.dtype(kinds.split()[0]).name
            raise FormatError(path, f"{element.name}.{name}", f"has type {dtype.name}, expected {want}")


STANDARD_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity") + tuple(
    f"{p}_{i}" for p, k in (("scale", 3), ("rot", 4)) for i in range(k)
)


def _check(ply, path: Path) -> bool:
    """Validate the element/property schema; True when the file is the compressed form."""
    names = [element.name for element in ply.elements]
    if "vertex" not in names:
        raise FormatError(path, "vertex", "element is missing")
    vertex = ply["vertex"]
    if "chunk" not in names:
        _require(vertex, STANDARD_REQUIRED, "f4 f8 f2", path)
        return False
    chunk = ply["chunk"]
    has_colour = "min_r" in {p.name for p in chunk.properties}
    _require(chunk, CHUNK_POS + CHUNK_SCALE + (CHUNK_COLOR if has_colour else ()), "f4", path)
    _require(vertex, PACKED, "u4", path)
    n = vertex.count
    if chunk.count != (n + CHUNK - 1) // CHUNK:
        raise FormatError(path, "chunk", f"{chunk.count} chunks cannot hold {n} splats (256 per chunk)")
    if "sh" in names:
        sh = ply["sh"]
        if len(sh.properties) not in SH_COUNTS:
            raise FormatError(path, "sh", f"{len(sh.properties)} properties, expected one of {SH_COUNTS}")
        _require(sh, tuple(f"f_rest_{i}" for i in range(len(sh.properties))), "u1", path)
        if sh.count != n:
            raise FormatError(path, "sh", f"{sh.count} rows for {n} splats")
    return True


def check_gaussian_ply(path: str | Path) -> int:
    """Cheap structural check (header, schema, body size) without decoding; returns the splat count.

    Raises:
        FormatError: naming the file and the element/property at fault.
    """
    path = Path(path)
    ply = _open(path)
    _check(ply, path)
    return int(ply["vertex"].count)


def read_gaussian_ply(path: str | Path) -> GaussianCloud:
    """Read either PLY form (compressed when a ``chunk`` element with packed vertices is present).

    Raises:
        FormatError: missing, truncated or malformed file, naming the element/property at fault.
    """
    path = Path(path)
    ply = _open(path)
    compressed = _check(ply, path)
    try:
        cloud = _read_compressed(ply, path) if compressed else _read_standard(ply["vertex"], path)
    except (ValueError, IndexError) as exc:  # truncated bodies surface here in plyfile's lazy reads
        raise FormatError(path, "vertex", f"truncated or malformed data ({exc})") from exc
    _check_finite(cloud, path)
    if VIEWER_FRAME_COMMENT in ply.comments:
        cloud = _turned(cloud, inverse=True)
    return cloud


def _turned(cloud: GaussianCloud, inverse: bool = False) -> GaussianCloud:
    """The cloud turned +90° about x (SONG → viewer frame), or back with ``inverse``."""
    from song.datasets.scenes._ply_kernel import turn_quats
    from song.geometry.rotations import quat_conj

    means = np.asarray(cloud.means, dtype=np.float32)
    x, y, z = means[:, 0], means[:, 1], means[:, 2]
    means = np.column_stack([x, z, -y] if inverse else [x, -z, y])  # exact: a quarter turn permutes and negates
    turn = quat_conj(TURN_TO_VIEWER) if inverse else TURN_TO_VIEWER
    quats = turn_quats(np.asarray(turn, dtype=np.float64), np.ascontiguousarray(cloud.quats, dtype=np.float32))
    return GaussianCloud(means, quats, cloud.log_scales, cloud.opacity_logits, cloud.sh_dc, cloud.sh_rest)


def _check_finite(cloud: GaussianCloud, path: Path) -> None:
    """Refuse splats holding NaN or inf (one NaN colour blackens whatever it covers in every render).

    Raises:
        FormatError: naming the field and how many splats hold a non-finite value.
    """
    fields = {"position": cloud.means, "rotation": cloud.quats, "scale": cloud.log_scales,
              "opacity": cloud.opacity_logits, "colour (f_dc)": cloud.sh_dc}  # fmt: skip
    if cloud.sh_rest is not None:
        fields["colour (f_rest)"] = cloud.sh_rest
    for name, values in fields.items():
        bad = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1) if len(values) else np.zeros(0, bool)
        if bad.any():
            raise FormatError(path, f"vertex {name}", f"{int(bad.sum()):,} of {len(values):,} splats hold NaN or inf")


def _read_standard(vertex, path: Path) -> GaussianCloud:
    col = lambda name: _column(vertex, name, path).astype(np.float32)  # noqa: E731
    rest_names = sorted(
        (p.name for p in vertex.properties if p.name.startswith("f_rest_")), key=lambda n: int(n.split("_")[-1])
    )
    rest = None
    if rest_names:
        if len(rest_names) % 3:
            raise FormatError(path, "vertex.f_rest_*", f"{len(rest_names)} values is not a multiple of 3")
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


def _ranges(chunk, names: tuple[str, ...], index: np.ndarray, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Per-splat (lo, hi) of a 6-name min/max chunk group, (N, 3) float64 each."""
    cols = [_column(chunk, name, path).astype(np.float64)[index] for name in names]
    return np.stack(cols[:3], axis=1), np.stack(cols[3:], axis=1)


def _lerp(lo: np.ndarray, hi: np.ndarray, t: np.ndarray) -> np.ndarray:
    return lo * (1 - t) + hi * t  # exact at both ends


def _read_compressed(ply, path: Path) -> GaussianCloud:
    chunk, vertex = ply["chunk"], ply["vertex"]
    n = vertex.count
    packed = {name: _column(vertex, name, path).astype(np.uint32) for name in PACKED}
    index = np.arange(n) // CHUNK
    means = _lerp(*_ranges(chunk, CHUNK_POS, index, path), _unpack_111011(packed["packed_position"]))
    log_scales = _lerp(*_ranges(chunk, CHUNK_SCALE, index, path), _unpack_111011(packed["packed_scale"]))
    word = packed["packed_color"]
    rgba = np.stack([_unorm(word, s, 8) for s in (24, 16, 8, 0)], axis=1)
    colour = rgba[:, :3]
    if "min_r" in {prop.name for prop in chunk.properties}:  # the 18-property chunk variant
        colour = _lerp(*_ranges(chunk, CHUNK_COLOR, index, path), colour)
    alpha = np.clip(rgba[:, 3], OPACITY_EPS, 1 - OPACITY_EPS)  # byte 255 → 1.0 would be an infinite logit
    rest = None
    if "sh" in [e.name for e in ply.elements]:
        sh = ply["sh"]
        v = np.stack([np.asarray(sh[f"f_rest_{i}"], dtype=np.float64) for i in range(len(sh.properties))], axis=1)
        unit = np.where(v == 0, 0.0, np.where(v == 255, 1.0, (v + 0.5) / 256))
        rest = ((unit - 0.5) * 8.0).reshape(n, 3, -1).transpose(0, 2, 1).astype(np.float32)
    return GaussianCloud(
        means=means.astype(np.float32),
        quats=_unpack_rotation(packed["packed_rotation"]).astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        opacity_logits=np.log(alpha / (1 - alpha)).astype(np.float32),
        sh_dc=((colour - 0.5) / SH_C0).astype(np.float32),
        sh_rest=rest,
    )


def _unpack_rotation(word: np.ndarray) -> np.ndarray:
    abc = np.stack([_unorm(word, 20, 10), _unorm(word, 10, 10), _unorm(word, 0, 10)], axis=1)
    abc = (abc - 0.5) / SQRT1_2
    largest = (word >> np.uint32(30)).astype(np.int64)
    m = np.sqrt(np.clip(1.0 - (abc**2).sum(axis=1), 0.0, None))
    out = np.empty((len(word), 4))
    for k in range(4):
        rows = largest == k
        out[np.ix_(rows, [i for i in range(4) if i != k])] = abc[rows]
        out[rows, k] = m[rows]
    return out


def pack_vertices_reference(
    means, pos_lo, pos_hi, log_scales, scale_lo, scale_hi, colours, colour_lo, colour_hi, opacity, quats, chunk, *_
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The plain numpy twin of :func:`song.datasets.scenes._ply_kernel.pack_vertices` (same arguments, same words)."""
    index = np.arange(len(means)) // chunk
    fraction = {k: _fraction(v, lo[index], hi[index]) for k, (v, lo, hi) in
                {"pos": (means, pos_lo, pos_hi), "scale": (log_scales, scale_lo, scale_hi),
                 "colour": (colours, colour_lo, colour_hi)}.items()}  # fmt: skip
    rgba = [_pack_unorm(fraction["colour"][:, k], 8) for k in range(3)] + [_pack_unorm(opacity, 8)]
    colour = (rgba[0] << 24) | (rgba[1] << 16) | (rgba[2] << 8) | rgba[3]
    return _pack_111011(fraction["pos"]), _pack_rotation(quats), _pack_111011(fraction["scale"]), colour


def _pack_unorm(t: np.ndarray, bits: int) -> np.ndarray:
    top = (1 << bits) - 1
    return np.clip(np.floor(t * top + 0.5), 0, top).astype(np.uint32)


_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])  # the three components stored per largest


def _pack_rotation(q: np.ndarray) -> np.ndarray:
    """Smallest-three words of unit quaternions ``q`` (N, 4)."""
    largest = np.argmax(np.abs(q), axis=1)  # first of equal magnitudes, as SuperSplat
    sign = np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)  # q ≡ −q: make the largest positive
    t = _pack_unorm(np.take_along_axis(q, _OTHERS[largest], axis=1) * sign[:, None] * SQRT1_2 + 0.5, 10)
    return (
        (largest.astype(np.uint32) << np.uint32(30)) | (t[:, 0] << np.uint32(20)) | (t[:, 1] << np.uint32(10)) | t[:, 2]
    )


def _pack_111011(t: np.ndarray) -> np.ndarray:
    return (
        (_pack_unorm(t[:, 0], 11) << np.uint32(21))
        | (_pack_unorm(t[:, 1], 10) << np.uint32(11))
        | _pack_unorm(t[:, 2], 11)
    )


def _chunk_ranges(values: np.ndarray, n_chunks: int) -> tuple[np.ndarray, np.ndarray]:
    """(n_chunks, D) min and max; the last chunk is padded with copies of the last row."""
    columns = np.empty((values.shape[1], n_chunks * CHUNK))  # one contiguous row per dimension: fast reductions
    columns[:, : len(values)] = values.T
    columns[:, len(values) :] = values[-1:].T
    columns = columns.reshape(values.shape[1], n_chunks, CHUNK)
    return columns.min(axis=2).T, columns.max(axis=2).T


def _fraction(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """SuperSplat's normalise: 0 at or below lo, 1 at or above hi, 0 for a range under 1e-5."""
    span = hi - lo
    t = (values - lo) / np.where(span < MIN_SPAN, 1.0, span)
    t = np.where(span < MIN_SPAN, 0.0, t)
    return np.where(values <= lo, 0.0, np.where(values >= hi, 1.0, t))


def morton_order(means: np.ndarray) -> np.ndarray:
    """Indices that sort ``means`` (N, 3) by 30-bit Morton code, as SuperSplat orders splats.

    Each axis of the bounding box is cut into 1024 cells (x in the lowest bit); runs of more than 256
    equal codes are re-sorted within their own bounding box. Stable, so the result is deterministic.
    """
    result = np.arange(len(means))
    stack = [(0, len(means))]
    while stack:
        start, end = stack.pop()
        idx = result[start:end]
        p = means[idx].astype(np.float64)
        lo, size = p.min(axis=0), np.ptp(p, axis=0)
        if not np.isfinite(size).all() or not size.any():
            continue
        cells = np.minimum(1023, (p - lo) * np.where(size > 0, 1024 / np.where(size > 0, size, 1), 0)).astype(np.uint32)
        code = (
            _part1by2(cells[:, 0]) | (_part1by2(cells[:, 1]) << np.uint32(1)) | (_part1by2(cells[:, 2]) << np.uint32(2))
        )
        sort = np.argsort(code, kind="stable")
        result[start:end] = idx[sort]
        code = code[sort]
        bounds = np.flatnonzero(np.diff(code)) + 1
        edges = np.concatenate([[0], bounds, [len(code)]])
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            if b - a > CHUNK:
                stack.append((start + int(a), start + int(b)))
    return result


def _part1by2(x: np.ndarray) -> np.ndarray:
    """Spread the low 10 bits of ``x`` (uint32) two zero bits apart."""
    x = x & np.uint32(0x3FF)
    x = (x ^ (x << np.uint32(16))) & np.uint32(0xFF0000FF)
    x = (x ^ (x << np.uint32(8))) & np.uint32(0x0300F00F)
    x = (x ^ (x << np.uint32(4))) & np.uint32(0x030C30C3)
    return (x ^ (x << np.uint32(2))) & np.uint32(0x09249249)


def _ply_bytes(elements: list, comments: list[str] = ()) -> bytes:
    from plyfile import PlyData

    buffer = io.BytesIO()
    PlyData(elements, text=False, byte_order="<", comments=list(comments)).write(buffer)
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


def write_compressed_ply(
    path: str | Path, cloud: GaussianCloud, *, morton: bool = False, viewer_frame: bool = False
) -> None:
    """Write the SuperSplat compressed PLY (18-property chunks, plus ``sh`` when present), atomically.

    Args:
        path: output file.
        cloud: N ≥ 1 Gaussians; ``sh_rest`` with 3, 8 or 15 coefficients if present.
        morton: sort splats in SuperSplat's Morton order first; by default the cloud's own order is
            kept (callers sort spatially for tight chunks) so splat i read back is splat i written.
        viewer_frame: store the cloud turned into the frame 3DGS viewers show upright (see the module
            docstring); only for SH degree 0, which a rotation leaves as it is.

    The bytes depend only on the cloud (and ``morton``).
    """
    from plyfile import PlyElement

    n = len(cloud)
    if n == 0:
        raise ValueError("cannot write an empty Gaussian cloud")
    if cloud.sh_rest is not None and cloud.sh_rest.shape[1] * 3 not in SH_COUNTS:
        raise ValueError(f"sh_rest has {cloud.sh_rest.shape[1]} coefficients; compressed PLY holds 3, 8 or 15")
    comments = []
    if viewer_frame:
        if cloud.sh_rest is not None:
            raise ValueError("viewer_frame needs SH degree 0: higher SH bands would have to be rotated too")
        cloud, comments = _turned(cloud), [VIEWER_FRAME_COMMENT]
    if morton:
        order = morton_order(cloud.means)
        cloud = GaussianCloud(*(None if a is None else a[order] for a in vars(cloud).values()))
    n_chunks = (n + CHUNK - 1) // CHUNK
    groups = {
        CHUNK_POS: cloud.means.astype(np.float64),
        CHUNK_SCALE: cloud.log_scales.astype(np.float64),
        CHUNK_COLOR: 0.5 + SH_C0 * cloud.sh_dc.astype(np.float64),
    }
    chunk = np.empty(n_chunks, dtype=[(name, "<f4") for name in CHUNK_POS + CHUNK_SCALE + CHUNK_COLOR])
    ranges = []
    for names, values in groups.items():
        lo, hi = _chunk_ranges(values, n_chunks)
        if names is CHUNK_SCALE:
            lo, hi = np.clip(lo, -SCALE_LIMIT, SCALE_LIMIT), np.clip(hi, -SCALE_LIMIT, SCALE_LIMIT)
        for k in range(3):
            chunk[names[k]], chunk[names[k + 3]] = lo[:, k], hi[:, k]
        # quantise against the float32 ranges actually stored, so decoding sees the same bounds
        ranges.append(
            (values, *(np.stack([chunk[names[k + j]] for k in range(3)], 1).astype(np.float64) for j in (0, 3)))
        )
    opacity = 1.0 / (1.0 + np.exp(-cloud.opacity_logits.astype(np.float64)))
    quats = cloud.quats.astype(np.float64)
    quats = quats / np.linalg.norm(quats, axis=1, keepdims=True)
    vertex = np.empty(n, dtype=[(name, "<u4") for name in PACKED])
    words = pack_vertices(*ranges[0], *ranges[1], *ranges[2], opacity, quats, CHUNK, MIN_SPAN, SQRT1_2)
    vertex["packed_position"], vertex["packed_rotation"], vertex["packed_scale"], vertex["packed_color"] = words
    elements = [PlyElement.describe(chunk, "chunk"), PlyElement.describe(vertex, "vertex")]
    if cloud.sh_rest is not None:
        flat = cloud.sh_rest.transpose(0, 2, 1).reshape(n, -1).astype(np.float64)  # channel-major
        q = np.clip(np.trunc((flat / 8.0 + 0.5) * 256), 0, 255).astype(np.uint8)
        sh = np.empty(n, dtype=[(f"f_rest_{i}", "u1") for i in range(flat.shape[1])])
        for i in range(flat.shape[1]):
            sh[f"f_rest_{i}"] = q[:, i]
        elements.append(PlyElement.describe(sh, "sh"))
    write_bytes_atomic(path, _ply_bytes(elements, comments))
