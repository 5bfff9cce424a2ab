"""The light baker: irradiance at every scene surfel from the scene's lights, with shadows and bounces.

Each surfel's colour becomes ``sRGB(clip(ρ · E / π · 2^EV))``: its albedo ρ (the material texture,
linearised) times the irradiance E it receives, in linear light, then Cycles' "Standard" view (the
exposure, then the sRGB transfer). E has three parts:

- **direct**, per *texel* (the surfels of one 10 cm cell, 2 cm deep along the normal, facing one of
  six axis directions): a rectangle light by Lambert's polygon formula (the rectangle clipped to the
  texel's horizon; a point source beyond 6 half-sizes), a point light by ``I cos θ / r²``, each times
  its visibility: one shadow ray per texel and light, towards a point on the light that changes
  from texel to texel (a rank-1 lattice), cast through Embree (``embreex``) against the scene's proxy
  mesh. Lights giving a texel under 1 % of its light cast no ray and take the others' shadowed
  share. The shadowed share is blurred along the surface (two passes of a 3 × 3 binomial filter over
  its texels: one ray per light is noise in a penumbra), and a surfel's value is interpolated
  trilinearly between the texels around it (penumbrae of ~0.2–0.3 m, as ceiling panels cast);
- **indirect** (diffuse inter-reflection), per 30 cm texel: 32 cosine-distributed rays gather the
  radiance ``ρ E / π`` of the 10 cm texels they hit (a proxy face without surfels: the largest texel
  of the 30 cm one there). The rays are cast once and kept as a sparse matrix; bounces are products
  with it, iterated until one adds under 0.5 % (indoors a median 6–20 % of a surface's light arrives
  after the third bounce, ``benchmarks/lighting.py`` measures it), then blurred
  along each surface (two passes of a 3 × 3 binomial filter over its texels). The procedural
  ambient occlusion (contacts, inside corners, undersides), which the 30 cm texels cannot resolve,
  scales this indirect part.

Emitting surfaces are drawn, not lit: surfels inside a light's rectangle (a window's glazing on the
wall, a ceiling panel on the ceiling: the whole rectangle that emits, as a renderer shows an area
light) show its radiance. Every step is
deterministic (fixed ray patterns; a ray's answer does not depend on how the casts are split over
threads), so a bake is byte-identical whatever the worker and thread count.

The baker also fills an **irradiance probe grid** (every 0.5 m over the floor, 1 m up): the mean
irradiance over all orientations, direct (shadow-tested) and indirect, so that avatars are lit by the
same light (:func:`probe_irradiance`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from song.datasets.scenes.lights import LightRig
from song.datasets.scenes.materials import linear_to_srgb

TEXEL_M = 0.10  # shadow cache cell
COARSE_M = 0.30  # indirect cache cell
GATHER_RAYS = 32
BOUNCES = 32  # at most; the gather stops when a bounce adds under BOUNCE_TOLERANCE
BOUNCE_TOLERANCE = 0.005
PROBE_SPACING_M, PROBE_HEIGHT_M, PROBE_RAYS = 0.5, 1.0, 48
RAY_OFFSET_M = 0.02  # ray origins leave the surface along its normal by this much
MIDDLE_GREY = 0.18  # auto exposure: the median surface radiance maps to this
DEPTH_M = 0.02  # texel cells' depth along their normal axis
MINOR_SHARE = 0.01  # lights under this share of a texel's unshadowed light cast no shadow ray from it
SHADOW_BLUR_PASSES = 2  # [1 2 1]² passes over the 10 cm texels: penumbrae of ~0.2–0.3 m, as ceiling panels cast
NEAR_FIELD = 6.0  # a rect light is integrated exactly within this many half-sizes (a point source beyond: < 1 % off)
_LUMA = np.array([0.2126, 0.7152, 0.0722])
_AXES = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]])


def tone(radiance: np.ndarray, exposure_ev: float) -> np.ndarray:
    """Display values of linear ``radiance``: ×2^EV, clipped to [0, 1], sRGB-encoded (Cycles' "Standard" view)."""
    return linear_to_srgb(np.clip(np.asarray(radiance, dtype=np.float64) * 2.0**exposure_ev, 0.0, 1.0))


@dataclass(frozen=True)
class LightTable:
    """A rig's lights as arrays for the kernels: kind (0 rect, 1 point), centre, u, v, n, half sizes, scale, colour.

    ``scale`` is a rect light's radiance or a point light's intensity (W/sr).
    """

    kind: np.ndarray
    centre: np.ndarray
    u: np.ndarray
    v: np.ndarray
    n: np.ndarray
    half: np.ndarray
    scale: np.ndarray
    colour: np.ndarray
    radius: np.ndarray

    @classmethod
    def of(cls, rig: LightRig) -> LightTable:
        """The table of a rig."""
        lights = rig.lights
        k = len(lights)
        frames = [light.frame() for light in lights]

        def arr(f, width: int = 3) -> np.ndarray:
            return np.array([f(i) for i in range(k)], dtype=np.float64).reshape(k, width)

        return cls(
            kind=np.array([0 if light.kind == "rect" else 1 for light in lights], dtype=np.int64),
            centre=arr(lambda i: lights[i].position),
            u=arr(lambda i: frames[i][0]),
            v=arr(lambda i: frames[i][1]),
            n=arr(lambda i: frames[i][2]),
            half=arr(lambda i: (lights[i].size[0] / 2, lights[i].size[1] / 2), 2),
            scale=np.array(
                [light.radiance if light.kind == "rect" else light.power_w / (4 * math.pi) for light in lights]
            ),
            colour=arr(lambda i: lights[i].colour),
            radius=np.array([light.radius for light in lights], dtype=np.float64),
        )

    def __len__(self) -> int:
        return len(self.kind)


# ---------------------------------------------------------------------------------------------- kernels


@nb.njit(cache=True, inline="always")  # inlined: 2.5× faster over a venue's texels × lights, same values
def _irradiance_one(p, nrm, kind, c, u, v, ln, half, scale, radius):
    """Unshadowed irradiance at point ``p`` with normal ``nrm`` from one light (per unit of its colour)."""
    dx, dy, dz = c[0] - p[0], c[1] - p[1], c[2] - p[2]
    d2 = dx * dx + dy * dy + dz * dz
    if kind == 1:
        d2 = max(d2, radius * radius)
        d = math.sqrt(d2)
        cos_r = (nrm[0] * dx + nrm[1] * dy + nrm[2] * dz) / d
        return scale * cos_r / d2 if cos_r > 0.0 else 0.0
    front = -(ln[0] * dx + ln[1] * dy + ln[2] * dz)  # receiver's height over the light's plane
    if front <= 0.0:
        return 0.0
    size = max(half[0], half[1])
    if d2 > (NEAR_FIELD * size) ** 2:
        d = math.sqrt(d2)
        cos_r = (nrm[0] * dx + nrm[1] * dy + nrm[2] * dz) / d
        if cos_r <= 0.0:
            return 0.0
        return scale * 4.0 * half[0] * half[1] * (front / d) * cos_r / d2
    # Lambert's formula over the rectangle clipped to the receiver's upper half-space: the edges (or
    # their parts) above the horizon, closed by the segment where the rectangle crosses it
    total = 0.0
    eps = 1e-9
    ex = ey = ez = 0.0  # where the outline leaves the half-space
    nx_ = ny_ = nz_ = 0.0  # where it comes back
    crossed = False
    for k in range(4):
        j = (k + 1) % 4
        ax, ay, az = _corner(k, dx, dy, dz, u, v, half)
        bx, by, bz = _corner(j, dx, dy, dz, u, v, half)
        ha = ax * nrm[0] + ay * nrm[1] + az * nrm[2]
        hb = bx * nrm[0] + by * nrm[1] + bz * nrm[2]
        if ha >= eps and hb >= eps:
            total += _edge(ax, ay, az, bx, by, bz, nrm)
        elif ha >= eps or hb >= eps:
            t = (eps - ha) / (hb - ha)
            cx, cy, cz = ax + t * (bx - ax), ay + t * (by - ay), az + t * (bz - az)
            crossed = True
            if ha >= eps:  # leaving
                total += _edge(ax, ay, az, cx, cy, cz, nrm)
                ex, ey, ez = cx, cy, cz
            else:  # coming back
                total += _edge(cx, cy, cz, bx, by, bz, nrm)
                nx_, ny_, nz_ = cx, cy, cz
    if crossed:
        total += _edge(ex, ey, ez, nx_, ny_, nz_, nrm)
    return scale * 0.5 * abs(total)


@nb.njit(cache=True, inline="always")
def _corner(k, dx, dy, dz, u, v, half):
    su = -1.0 if k == 0 or k == 3 else 1.0
    sv = -1.0 if k < 2 else 1.0
    return (
        dx + su * half[0] * u[0] + sv * half[1] * v[0],
        dy + su * half[0] * u[1] + sv * half[1] * v[1],
        dz + su * half[0] * u[2] + sv * half[1] * v[2],
    )


@nb.njit(cache=True, inline="always")
def _edge(ax, ay, az, bx, by, bz, nrm):
    """One edge's term of Lambert's formula: its angle seen from the receiver times n · (its plane's normal)."""
    la = math.sqrt(ax * ax + ay * ay + az * az)
    lb = math.sqrt(bx * bx + by * by + bz * bz)
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    lc = math.sqrt(cx * cx + cy * cy + cz * cz)
    if lc < 1e-15 or la < 1e-15 or lb < 1e-15:
        return 0.0
    cosg = min(1.0, max(-1.0, (ax * bx + ay * by + az * bz) / (la * lb)))
    return math.acos(cosg) * (cx * nrm[0] + cy * nrm[1] + cz * nrm[2]) / lc


@nb.njit(cache=True, parallel=True)
def _per_light(points, normals, kind, centre, u, v, n, half, scale, radius):
    """(M, L) unshadowed irradiance of M receivers from L lights."""
    out = np.zeros((len(points), len(kind)))
    for i in nb.prange(len(points)):
        for j in range(len(kind)):
            out[i, j] = _irradiance_one(points[i], normals[i], kind[j], centre[j], u[j], v[j], n[j], half[j],
                                        scale[j], radius[j])  # fmt: skip
    return out


@nb.njit(cache=True, inline="always")
def _slot(key, mask):
    """Home slot of ``key`` in a table of ``mask + 1`` slots (Fibonacci hashing: the product's high bits)."""
    return np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(24)) & mask


@nb.njit(cache=True)
def _key_table(keys):
    """Open-addressing table (a power of two ≥ 2 × K slots) of the row of each key (−1: empty)."""
    size = 16
    while size < 2 * len(keys):
        size *= 2
    slots = np.full(size, -1, dtype=np.int64)
    mask = size - 1
    for i in range(len(keys)):
        h = _slot(keys[i], mask)
        while slots[h] >= 0:
            h = (h + 1) & mask
        slots[h] = i
    return slots


@nb.njit(cache=True, inline="always")
def _find(keys, slots, key):
    """Row of ``key`` in ``keys`` through its table ``slots``, or −1 (linear probing)."""
    mask = len(slots) - 1
    h = _slot(key, mask)
    while True:
        i = slots[h]
        if i < 0 or keys[i] == key:
            return i
        h = (h + 1) & mask


@nb.njit(cache=True, parallel=True)
def _find_all(keys, slots, queries):  # pragma: no cover - compiled; twin: searchsorted (tested)
    out = np.empty(len(queries), dtype=np.int64)
    for i in nb.prange(len(queries)):
        out[i] = _find(keys, slots, queries[i])
    return out


@nb.njit(cache=True, parallel=True)
def _trilinear(pos, bucket, keys, slots, values, h, lo, dims):
    """Values (K, C) of the cells ``keys`` interpolated at ``pos`` between the 8 cells around it in its bucket.

    Missing cells drop out (weights renormalised); the surfel's own cell always exists.
    """
    out = np.zeros((len(pos), values.shape[1]))
    for i in nb.prange(len(pos)):
        axis = bucket[i] // 2
        fx = (pos[i, 0] - lo[0]) / (DEPTH_M if axis == 0 else h) - 0.5
        fy = (pos[i, 1] - lo[1]) / (DEPTH_M if axis == 1 else h) - 0.5
        fz = (pos[i, 2] - lo[2]) / (DEPTH_M if axis == 2 else h) - 0.5
        bx, by, bz = math.floor(fx), math.floor(fy), math.floor(fz)
        tx, ty, tz = fx - bx, fy - by, fz - bz
        wsum = 0.0
        for corner in range(8):
            ox, oy, oz = corner & 1, (corner >> 1) & 1, (corner >> 2) & 1
            w = (tx if ox else 1 - tx) * (ty if oy else 1 - ty) * (tz if oz else 1 - tz)
            if w <= 0.0:
                continue
            ix, iy, iz = bx + ox, by + oy, bz + oz
            if ix < 0 or iy < 0 or iz < 0 or ix >= dims[0] or iy >= dims[1] or iz >= dims[2]:
                continue
            key = ((ix * dims[1] + iy) * dims[2] + iz) * 6 + bucket[i]
            k = _find(keys, slots, key)
            if k >= 0:
                for c in range(values.shape[1]):
                    out[i, c] += w * values[k, c]
                wsum += w
        if wsum > 0.0:
            for c in range(values.shape[1]):
                out[i, c] /= wsum
    return out


# ---------------------------------------------------------------------------------------------- texels


def buckets(normals: np.ndarray) -> np.ndarray:
    """Index (0..5) of the axis direction (+x, −x, +y, −y, +z, −z) nearest each normal (the first on a tie)."""
    return _buckets(np.ascontiguousarray(normals, dtype=np.float64))


@nb.njit(cache=True, parallel=True)
def _buckets(normals):  # pragma: no cover - compiled; twin: argmax(normals @ _AXES.T) (tested)
    out = np.empty(len(normals), dtype=np.int64)
    for i in nb.prange(len(normals)):
        best, value = 0, normals[i, 0]
        for axis in range(3):
            for sign in range(2):
                v = normals[i, axis] if sign == 0 else -normals[i, axis]
                if v > value:
                    best, value = 2 * axis + sign, v
        out[i] = best
    return out


@dataclass
class Texels:
    """Surfels grouped by (cell of ``h`` metres, normal bucket): sorted keys and per-texel means."""

    h: float
    lo: np.ndarray
    dims: np.ndarray
    keys: np.ndarray
    index: np.ndarray  # texel of each surfel
    pos: np.ndarray
    normal: np.ndarray
    count: np.ndarray
    slots: np.ndarray  # hash table of ``keys`` (:func:`_key_table`): the texel of a key in O(1)

    @classmethod
    def of(cls, pos, normals, bucket, h: float, lo: np.ndarray, dims: np.ndarray, weight=None) -> Texels:
        """Group points (surfels, or finer texels with their ``weight``) into texels of ``h`` m on the grid ``lo``, ``dims``."""
        keys = cell_keys(pos, bucket, h, lo, dims)
        uniq, index = group_keys(keys)
        w = np.ones(len(pos)) if weight is None else np.ascontiguousarray(weight, dtype=np.float64)
        count, sums = _weighted_sums(
            index, np.ascontiguousarray(pos, dtype=np.float64), np.ascontiguousarray(normals, dtype=np.float64), w,
            len(uniq),
        )  # fmt: skip
        total = sums / np.maximum(count, 1e-12)[:, None]
        return cls(h, lo, dims, uniq, index, total[:, :3], _unit(total[:, 3:]), count, _key_table(uniq))

    def find(self, keys: np.ndarray) -> np.ndarray:
        """The texel of each key, or −1."""
        return _find_all(self.keys, self.slots, np.ascontiguousarray(keys, dtype=np.int64))

    def cells(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) integer cells and (K,) buckets of the texels (the inverse of :func:`cell_keys`)."""
        flat, bucket = self.keys // 6, self.keys % 6
        d1, d2 = self.dims[1], self.dims[2]
        return np.column_stack([flat // (d1 * d2), (flat // d2) % d1, flat % d2]), bucket

    def centres(self) -> np.ndarray:
        """(K, 3) where the interpolation places each texel's value.

        Its cell's centre across its normal axis, its surfels' mean along it (on a flat texel's surface).
        """
        cell, bucket = self.cells()
        out = self.lo + (cell + 0.5) * self.h
        axis = bucket // 2
        rows = np.arange(len(out))
        out[rows, axis] = self.pos[rows, axis]
        return out

    def blur(self, values: np.ndarray, passes: int = 2) -> np.ndarray:
        """``values`` (K, C) smoothed across each texel's surface, ``passes`` times.

        A [1 2 1]² filter over its in-plane neighbours that exist (same bucket and depth cell).
        """
        cell, bucket = self.cells()
        values = np.ascontiguousarray(values, dtype=np.float64)
        return _blur(cell, bucket, self.keys, self.slots, self.dims, values, int(passes))

    def mean(self, values: np.ndarray) -> np.ndarray:
        """Per-texel means of per-surfel ``values`` (N, C)."""
        return mean_by(self.index, values, len(self.keys))

    def lookup(self, pos: np.ndarray, bucket: np.ndarray) -> np.ndarray:
        """The texel at each point and bucket, or −1."""
        return self.find(cell_keys(pos, bucket, self.h, self.lo, self.dims))

    def interpolate(self, pos: np.ndarray, bucket: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Per-texel ``values`` (K, C) interpolated at points in ``bucket`` (see :func:`_trilinear`)."""
        return _trilinear(pos, bucket, self.keys, self.slots, np.ascontiguousarray(values, dtype=np.float64), self.h,
                          self.lo, self.dims)  # fmt: skip


def cell_keys(pos: np.ndarray, bucket: np.ndarray, h: float, lo: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """int64 key of (cell, bucket); cells are ``h`` wide across the bucket's axis and :data:`DEPTH_M` along it.

    The thin cells along the normal keep parallel faces a few centimetres apart (a trim on a wall's
    end, a shelf board over another) in different texels.
    """
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    return _cell_keys(pos, np.ascontiguousarray(bucket, dtype=np.int64), float(h), np.asarray(lo, np.float64),
                      np.asarray(dims, np.int64))  # fmt: skip


@nb.njit(cache=True, parallel=True)
def _cell_keys(pos, bucket, h, lo, dims):  # pragma: no cover - compiled; twin: the numpy expression (tested)
    out = np.empty(len(pos), dtype=np.int64)
    for i in nb.prange(len(pos)):
        axis = bucket[i] // 2
        c0 = min(max(np.int64(math.floor((pos[i, 0] - lo[0]) / (DEPTH_M if axis == 0 else h))), 0), dims[0] - 1)
        c1 = min(max(np.int64(math.floor((pos[i, 1] - lo[1]) / (DEPTH_M if axis == 1 else h))), 0), dims[1] - 1)
        c2 = min(max(np.int64(math.floor((pos[i, 2] - lo[2]) / (DEPTH_M if axis == 2 else h))), 0), dims[2] - 1)
        out[i] = ((c0 * dims[1] + c1) * dims[2] + c2) * 6 + bucket[i]
    return out


def _encode(cell: np.ndarray, bucket: np.ndarray, dims: np.ndarray) -> np.ndarray:
    return ((cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]) * 6 + bucket


@nb.njit(cache=True, parallel=True)
def _blur(cell, bucket, keys, slots, dims, values, passes):  # pragma: no cover - compiled; twin: blur_reference
    k, channels = values.shape
    taps = np.empty((k, 9), dtype=np.int64)
    weights = np.empty((k, 9))
    for i in nb.prange(k):
        axis = bucket[i] // 2
        t = 0
        total = 0.0
        for o1 in range(-1, 2):
            for o2 in range(-1, 2):
                c0, c1, c2 = cell[i, 0], cell[i, 1], cell[i, 2]
                if axis == 0:
                    c1, c2 = c1 + o1, c2 + o2
                elif axis == 1:
                    c2, c0 = c2 + o1, c0 + o2
                else:
                    c0, c1 = c0 + o1, c1 + o2
                found = _find(keys, slots, ((c0 * dims[1] + c1) * dims[2] + c2) * 6 + bucket[i])
                taps[i, t] = found if found >= 0 else i
                weights[i, t] = (2 - abs(o1)) * (2 - abs(o2)) if found >= 0 else 0.0
                total += weights[i, t]
                t += 1
        for t in range(9):
            weights[i, t] /= total
    out = values
    for _ in range(passes):
        nxt = np.empty_like(out)
        for i in nb.prange(k):
            for ch in range(channels):
                acc = weights[i, 0] * out[taps[i, 0], ch]
                for t in range(1, 9):
                    acc += weights[i, t] * out[taps[i, t], ch]
                nxt[i, ch] = acc
        out = nxt
    return out


def blur_reference(texels: Texels, values: np.ndarray, passes: int = 2) -> np.ndarray:
    """The plain numpy twin of :meth:`Texels.blur` (tests)."""
    cell, bucket = texels.cells()
    axis = bucket // 2
    a1, a2 = (axis + 1) % 3, (axis + 2) % 3
    rows = np.arange(len(cell))
    neighbours, weights = [], []
    for o1 in (-1, 0, 1):
        for o2 in (-1, 0, 1):
            c = cell.copy()
            c[rows, a1] += o1
            c[rows, a2] += o2
            k = texels.find(_encode(c, bucket, texels.dims))
            found = k >= 0
            neighbours.append(np.where(found, k, rows))
            weights.append(np.where(found, (2 - abs(o1)) * (2 - abs(o2)), 0.0))
    weights = np.array(weights, dtype=np.float64)
    weights /= weights.sum(axis=0)
    out = values
    for _ in range(passes):
        out = sum(w[:, None] * out[n] for n, w in zip(neighbours, weights, strict=True))
    return out


def mean_by(index: np.ndarray, values: np.ndarray, k: int) -> np.ndarray:
    """Means of ``values`` rows grouped by ``index`` (0..k−1)."""
    values = values.reshape(len(values), -1)
    return sum_by(index, values, k) / np.maximum(np.bincount(index, minlength=k), 1)[:, None]


def sum_by(index: np.ndarray, values: np.ndarray, k: int) -> np.ndarray:
    """(k, C) float sums of ``values`` (M, C) rows grouped by ``index`` (0..k−1), added in row order.

    One compiled pass over the rows; the sums are those of ``np.bincount(index, weights=values[:, c])``
    per column, bit for bit (the same additions in the same order).
    """
    values = np.ascontiguousarray(values, dtype=np.float64).reshape(len(values), -1)
    return _sum_rows(np.ascontiguousarray(index, dtype=np.int64), values, int(k))


@nb.njit(cache=True)
def _sum_rows(index, values, k):  # pragma: no cover - compiled; twin: np.bincount per column (tested)
    out = np.zeros((k, values.shape[1]))
    for i in range(len(index)):
        for c in range(values.shape[1]):
            out[index[i], c] += values[i, c]
    return out


@nb.njit(cache=True)
def _weighted_sums(index, pos, normals, w, k):  # pragma: no cover - compiled; twin: sum_by of [pos, normals]·w
    """Per group of ``index``: the sum of the weights ``w`` (k,) and of ``[pos, normals]·w`` rows (k, 6), in row order.

    The products and additions of ``sum_by(index, np.hstack([pos, normals]) * w[:, None], k)``, without its
    (N, 6) temporaries.
    """
    count = np.zeros(k)
    sums = np.zeros((k, 6))
    for i in range(len(index)):
        g, wi = index[i], w[i]
        count[g] += wi
        for c in range(3):
            sums[g, c] += pos[i, c] * wi
            sums[g, 3 + c] += normals[i, c] * wi
    return count, sums


def group_keys(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(keys, return_inverse=True)``: the sorted distinct keys and each key's row among them.

    Compiled: a hash table numbers the keys in first-seen order, then only the distinct ones are sorted
    (5× faster than sorting all of a scene's surfel keys, which repeat ~7× each).
    """
    return _group_keys(np.ascontiguousarray(keys, dtype=np.int64))


@nb.njit(cache=True)
def _group_keys(keys):  # pragma: no cover - compiled; twin: np.unique(return_inverse=True) (tested)
    n = len(keys)
    size = 16
    while size < 2 * n:
        size *= 2
    mask = size - 1
    slots = np.full(size, -1, dtype=np.int64)
    first = np.empty(n, dtype=np.int64)
    seen = np.empty(n, dtype=np.int64)
    count = 0
    for i in range(n):
        h = _slot(keys[i], mask)
        while True:
            s = slots[h]
            if s < 0:
                slots[h], first[count], seen[i] = count, i, count
                count += 1
                break
            if keys[first[s]] == keys[i]:
                seen[i] = s
                break
            h = (h + 1) & mask
    distinct = keys[first[:count]]
    order = np.argsort(distinct)
    rank = np.empty(count, dtype=np.int64)
    rank[order] = np.arange(count)
    index = np.empty(n, dtype=np.int64)
    for i in range(n):
        index[i] = rank[seen[i]]
    return distinct[order], index


def column_bounds(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column minima and maxima of a non-empty (N, C) array, as ``min(axis=0)`` and ``max(axis=0)``.

    Column by column: numpy's axis-0 reductions of an (N, 3) array are about 20× slower.
    """
    return (
        np.array([values[:, a].min() for a in range(values.shape[1])]),
        np.array([values[:, a].max() for a in range(values.shape[1])]),
    )


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


# ---------------------------------------------------------------------------------------------- rays


PARALLEL_RAYS = 65_536  # a query with at least this many rays is split over numba's threads


class Tracer:
    """Embree ray queries against a triangle soup (``embreex``: Intel Embree's BVH), deterministic.

    A large query is split into contiguous slices traced on numba's thread count (embreex releases the
    GIL: 2.1× on 2 cores); every ray's answer is its own, so the result does not depend on the split.
    """

    def __init__(self, triangles: np.ndarray) -> None:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        self._scene = rtcs.EmbreeScene()
        self.empty = len(triangles) == 0
        if not self.empty:
            TriangleMesh(self._scene, np.ascontiguousarray(triangles, dtype=np.float32))

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, dists: np.ndarray) -> np.ndarray:
        """True where a segment ``origin + t·dir``, 0 < t < dist, hits a triangle."""
        if self.empty or len(origins) == 0:
            return np.zeros(len(origins), bool)
        origins = np.ascontiguousarray(origins, dtype=np.float32)
        dirs = np.ascontiguousarray(dirs, dtype=np.float32)
        dists = np.ascontiguousarray(dists, dtype=np.float32)
        hit = self._split(
            lambda sl: np.asarray(self._scene.run(origins[sl], dirs[sl], query="OCCLUDED", dists=dists[sl])),
            len(origins),
        )
        return hit >= 0

    def intersect(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(distance or inf, hit, geometric normal (unit, facing the ray)) of the first hit along each ray."""
        n = len(origins)
        if self.empty or n == 0:
            return np.full(n, np.inf), np.zeros(n, bool), np.zeros((n, 3))
        o32, d32 = np.ascontiguousarray(origins, dtype=np.float32), np.ascontiguousarray(dirs, dtype=np.float32)

        def trace(sl: slice) -> np.ndarray:
            res = self._scene.run(o32[sl], d32[sl], output=1)
            return np.column_stack([np.asarray(res["geomID"]), np.asarray(res["tfar"]), np.asarray(res["Ng"])])

        res = self._split(trace, n)
        hit = res[:, 0] >= 0
        t = np.where(hit, res[:, 1].astype(np.float64), np.inf)
        ng = _unit(res[:, 2:5].astype(np.float64))
        ng = np.where(np.sum(ng * dirs, axis=1, keepdims=True) > 0, -ng, ng)
        return t, hit, ng

    @staticmethod
    def _split(trace, n: int) -> np.ndarray:
        """``trace(slice)`` over ``n`` rays, in contiguous slices on numba's threads when there are many."""
        parts = min(nb.get_num_threads(), max(1, n // PARALLEL_RAYS))
        if parts <= 1:
            return trace(slice(0, n))
        from concurrent.futures import ThreadPoolExecutor

        bounds = np.linspace(0, n, parts + 1).astype(int)
        with ThreadPoolExecutor(parts) as pool:
            slices = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
            return np.concatenate(list(pool.map(trace, slices)))


def _hemisphere(count: int) -> np.ndarray:
    """``count`` cosine-distributed directions around +z (a Fibonacci spiral on the disc, lifted)."""
    i = np.arange(count) + 0.5
    r = np.sqrt(i / count)
    a = i * math.pi * (3 - math.sqrt(5))
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.sqrt(np.maximum(0.0, 1 - r * r))])


def _sphere(count: int) -> np.ndarray:
    """``count`` directions spread evenly over the sphere (Fibonacci)."""
    i = np.arange(count) + 0.5
    z = 1 - 2 * i / count
    a = i * math.pi * (3 - math.sqrt(5))
    r = np.sqrt(1 - z * z)
    return np.column_stack([r * np.cos(a), r * np.sin(a), z])


def _frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(normals[:, 2:3]) < 0.9, np.array([[0.0, 0, 1]]), np.array([[1.0, 0, 0]]))
    t1 = _unit(np.cross(helper, normals))
    return t1, np.cross(normals, t1)


# ---------------------------------------------------------------------------------------------- the bake


@dataclass(frozen=True)
class ProbeGrid:
    """Mean irradiance over all orientations (RGB, W/m²) on a horizontal grid at :data:`PROBE_HEIGHT_M`.

    ``values[r, c]`` lies at ``origin + (c, r) · spacing``; ``exposure_ev`` is the scene's.
    """

    origin: tuple[float, float]
    spacing: float
    values: np.ndarray
    exposure_ev: float

    def to_json(self) -> str:
        """Compact JSON (values rounded to 4 significant digits)."""
        return json.dumps(
            {
                "origin": list(self.origin),
                "spacing": self.spacing,
                "shape": list(self.values.shape[:2]),
                "exposure_ev": self.exposure_ev,
                "values": [float(f"{v:.4g}") for v in self.values.ravel()],
            },
            separators=(",", ":"),
        )

    @classmethod
    def from_json(cls, text: str) -> ProbeGrid:
        """Inverse of :meth:`to_json`; ValueError on a malformed grid."""
        data = json.loads(text)
        rows, cols = (int(v) for v in data["shape"])
        values = np.asarray(data["values"], dtype=np.float64).reshape(rows, cols, 3)
        if not np.all(np.isfinite(values)) or (values < 0).any():
            raise ValueError("probe values must be finite and ≥ 0")
        return cls((float(data["origin"][0]), float(data["origin"][1])), float(data["spacing"]), values,
                   float(data["exposure_ev"]))  # fmt: skip


@dataclass
class Bake:
    """What :func:`bake` returns: per-surfel display colours and irradiance, the emitters' mask, the probes."""

    colour: np.ndarray
    irradiance: np.ndarray
    emissive: np.ndarray
    exposure_ev: float
    probes: ProbeGrid | None


def emissive_mask(pos: np.ndarray, normals: np.ndarray, table: LightTable) -> tuple[np.ndarray, np.ndarray]:
    """Surfels drawn as a light's face: within 3 cm behind a rect light and inside its rectangle; (mask, light)."""
    which = _emitters(pos, normals, table.kind, table.centre, table.u, table.v, table.n, table.half)
    return which >= 0, which


EMITTER_CELL_M = 1.0  # the xy grid that lists the rect lights whose slab can hold a surfel in each cell


@nb.njit(cache=True)
def _emitters(pos, normals, kind, centre, u, v, n, half):  # pragma: no cover - compiled; twin: _emitters_reference
    """The last rect light whose face holds each surfel, or −1; only the lights listed in its grid cell are tested."""
    which = np.full(len(pos), -1, dtype=np.int64)
    if len(pos) == 0 or len(kind) == 0:
        return which
    # each rect light's box (its rectangle, 3 cm behind and 5 mm before it) over a grid of xy cells
    x0, y0 = pos[:, 0].min(), pos[:, 1].min()
    cols = np.int64((pos[:, 0].max() - x0) / EMITTER_CELL_M) + 1
    rows = np.int64((pos[:, 1].max() - y0) / EMITTER_CELL_M) + 1
    box = np.empty((len(kind), 4), dtype=np.int64)
    count = np.zeros(rows * cols + 1, dtype=np.int64)
    for j in range(len(kind)):
        # half the box's extent along x and y
        rx = half[j, 0] * abs(u[j, 0]) + half[j, 1] * abs(v[j, 0]) + 0.03 * abs(n[j, 0]) + 1e-6
        ry = half[j, 0] * abs(u[j, 1]) + half[j, 1] * abs(v[j, 1]) + 0.03 * abs(n[j, 1]) + 1e-6
        c0 = min(max(np.int64(math.floor((centre[j, 0] - rx - x0) / EMITTER_CELL_M)), 0), cols - 1)
        c1 = min(max(np.int64(math.floor((centre[j, 0] + rx - x0) / EMITTER_CELL_M)), 0), cols - 1)
        r0 = min(max(np.int64(math.floor((centre[j, 1] - ry - y0) / EMITTER_CELL_M)), 0), rows - 1)
        r1 = min(max(np.int64(math.floor((centre[j, 1] + ry - y0) / EMITTER_CELL_M)), 0), rows - 1)
        box[j] = (c0, c1, r0, r1)
        if kind[j] == 0:
            for r in range(r0, r1 + 1):
                for c in range(c0, c1 + 1):
                    count[r * cols + c + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    listed = np.empty(start[-1], dtype=np.int64)
    for j in range(len(kind)):  # in light order, so the last match in a cell's list is the last light
        if kind[j] == 0:
            for r in range(box[j, 2], box[j, 3] + 1):
                for c in range(box[j, 0], box[j, 1] + 1):
                    listed[fill[r * cols + c]] = j
                    fill[r * cols + c] += 1
    for i in range(len(pos)):
        cell = min(np.int64((pos[i, 1] - y0) / EMITTER_CELL_M), rows - 1) * cols + min(
            np.int64((pos[i, 0] - x0) / EMITTER_CELL_M), cols - 1
        )
        for m in range(start[cell], start[cell + 1]):
            j = listed[m]
            dx, dy, dz = pos[i, 0] - centre[j, 0], pos[i, 1] - centre[j, 1], pos[i, 2] - centre[j, 2]
            behind = -(dx * n[j, 0] + dy * n[j, 1] + dz * n[j, 2])
            if behind <= -0.005 or behind >= 0.03:
                continue
            if normals[i, 0] * n[j, 0] + normals[i, 1] * n[j, 1] + normals[i, 2] * n[j, 2] <= 0.9:
                continue
            du = abs(dx * u[j, 0] + dy * u[j, 1] + dz * u[j, 2])
            dv = abs(dx * v[j, 0] + dy * v[j, 1] + dz * v[j, 2])
            if du < half[j, 0] and dv < half[j, 1]:
                which[i] = j
    return which


def _emitters_reference(pos, normals, kind, centre, u, v, n, half) -> np.ndarray:
    """The numpy twin of :func:`_emitters`: every surfel against every rect light (tests)."""
    which = np.full(len(pos), -1, dtype=np.int64)
    for j in np.flatnonzero(kind == 0):
        d = pos - centre[j]
        behind = -(d @ n[j])
        inside = (behind > -0.005) & (behind < 0.03) & (normals @ n[j] > 0.9)
        inside &= (np.abs(d @ u[j]) < half[j, 0]) & (np.abs(d @ v[j]) < half[j, 1])
        which[inside] = j
    return which


def bake(
    pos: np.ndarray,
    normals: np.ndarray,
    albedo: np.ndarray,
    ao: np.ndarray,
    triangles: np.ndarray,
    rig: LightRig,
    floor: tuple | None = None,
) -> Bake:
    """Light surfels (positions, unit normals, linear albedos (N, 3), ambient occlusion (N,)) by ``rig``.

    ``triangles`` (T, 3, 3) is the occluding proxy mesh; ``floor`` = ``(grid, floor_mask)`` places the
    probe grid (none without it).
    """
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    normals = np.ascontiguousarray(_unit(np.asarray(normals, dtype=np.float64)))
    table = LightTable.of(rig)
    tracer = Tracer(triangles)
    n = len(pos)
    emissive, which = emissive_mask(pos, normals, table)
    bucket = buckets(normals)
    # an odd offset keeps the usual planes (z = 0, the ceiling, walls on grid lines) off the cell boundaries
    lo, span = np.zeros(3), np.ones(3)
    if n:
        low, high = column_bounds(pos)
        lo = low - 2 * COARSE_M - 0.0137
        span = high + 2 * COARSE_M - lo
    dims = np.ceil(span / DEPTH_M).astype(np.int64) + 1  # bounds every axis at either cell size
    fine = Texels.of(pos, normals, bucket, TEXEL_M, lo, dims)
    fine_bucket = buckets(fine.normal)
    fine_direct = _direct(fine, table, tracer) if len(table) and n else np.zeros((len(fine.keys), 3))
    # emitters are counted as lights, not as reflectors
    fine_albedo = fine.mean(np.where(emissive[:, None], 0.0, albedo))
    coarse = Texels.of(fine.pos, fine.normal, fine_bucket, COARSE_M, lo, dims, fine.count)
    # the gather's noise (32 rays a texel) blurred along the surfaces: indirect light varies slowly
    indirect_coarse = coarse.blur(_gather(coarse, fine, fine_direct, fine_albedo, tracer))
    fine_indirect = coarse.interpolate(fine.pos, fine_bucket, indirect_coarse)
    both = fine.interpolate(pos, bucket, np.hstack([fine_direct, fine_indirect]))
    direct, indirect = both[:, :3], both[:, 3:] * ao[:, None]
    irradiance = direct + indirect
    radiance = albedo * irradiance / math.pi
    lum = radiance[~emissive] @ _LUMA
    exposure = rig.exposure_ev
    if exposure is None:
        median = float(np.median(lum)) if len(lum) else 1.0
        exposure = round(math.log2(MIDDLE_GREY / median), 2) if median > 0 else 0.0
    colour = tone(radiance, exposure)
    if emissive.any():
        j = which[emissive]
        colour[emissive] = tone(table.scale[j, None] * table.colour[j], exposure)
    probes = None
    if floor is not None:
        probes = _probes(floor, table, tracer, fine, coarse, fine_direct, fine_albedo, indirect_coarse, exposure)
    return Bake(colour, irradiance, emissive, float(exposure), probes)


def _direct(fine: Texels, table: LightTable, tracer: Tracer) -> np.ndarray:
    """(K, 3) direct RGB irradiance at each fine texel, shadow-tested.

    Lights giving a texel under :data:`MINOR_SHARE` of its unshadowed light cast no ray from it; they
    take the shadowed share of the others.
    """
    origin = fine.pos + fine.normal * RAY_OFFSET_M
    # the light is evaluated on the surface where the interpolation puts the value (off it, a ceiling or a
    # wall would see the panel or window set just before it); shadow rays leave from above the surfels' mean
    e = _per_light(fine.centres(), fine.normal, table.kind, table.centre, table.u, table.v, table.n, table.half,
                   table.scale, table.radius)  # fmt: skip
    tex, light, starts, dirs, reach = _shadow_rays(origin, e, MINOR_SHARE, RAY_OFFSET_M, table.kind, table.centre,
                                                   table.u, table.v, table.half, table.radius)  # fmt: skip
    blocked = tracer.occluded(starts, dirs, reach)
    ratio = _lit_share(tex, light, blocked, e, table.colour)
    # one ray per texel and light is noise in a penumbra: the shadowed share is blurred along the surface
    return (e @ table.colour) * fine.blur(ratio, SHADOW_BLUR_PASSES)


@nb.njit(cache=True)
def _lit_share(tex, light, blocked, e, colour):  # pragma: no cover - compiled; twin: _lit_share_reference
    """(K, 3) share of each texel's light (shadow rays weighted by their light's RGB irradiance) not blocked; 1 unlit."""
    k = e.shape[0]
    num = np.zeros((k, 3))
    den = np.zeros((k, 3))
    for r in range(len(tex)):
        i, j = tex[r], light[r]
        for c in range(3):
            w = e[i, j] * colour[j, c]
            num[i, c] += w * (0.0 if blocked[r] else 1.0)
            den[i, c] += w
    out = np.ones((k, 3))
    for i in range(k):
        for c in range(3):
            if den[i, c] > 0:
                out[i, c] = num[i, c] / max(den[i, c], 1e-30)
    return out


def _lit_share_reference(tex, light, blocked, e, colour) -> np.ndarray:
    """The numpy twin of :func:`_lit_share` (tests)."""
    w = e[tex, light][:, None] * colour[light]
    num = np.column_stack([np.bincount(tex, weights=(w * ~blocked[:, None])[:, c], minlength=len(e)) for c in range(3)])
    den = np.column_stack([np.bincount(tex, weights=w[:, c], minlength=len(e)) for c in range(3)])
    return np.where(den > 0, num / np.maximum(den, 1e-30), 1.0)


@nb.njit(cache=True, inline="always")
def _light_point(j, index, kind, centre, u, v, half, radius):
    """A point on light ``j`` picked by ``index`` on a rank-1 lattice (R2 sequence): over a rect, on a sphere."""
    g = 1.32471795724474602596
    i = index + 0.5
    a = ((i / g) % 1.0) * 2 - 1
    b = ((i / (g * g)) % 1.0) * 2 - 1
    if kind[j] == 0:
        return (
            centre[j, 0] + a * half[j, 0] * u[j, 0] + b * half[j, 1] * v[j, 0],
            centre[j, 1] + a * half[j, 0] * u[j, 1] + b * half[j, 1] * v[j, 1],
            centre[j, 2] + a * half[j, 0] * u[j, 2] + b * half[j, 1] * v[j, 2],
        )
    r = math.sqrt(max(0.0, 1 - a * a))
    t = math.pi * (b + 1)
    return (
        centre[j, 0] + radius[j] * r * math.cos(t),
        centre[j, 1] + radius[j] * r * math.sin(t),
        centre[j, 2] + radius[j] * a,
    )


@nb.njit(cache=True)
def _shadow_rays(origin, e, minor, short, kind, centre, u, v, half, radius):
    """One shadow ray per receiver and non-minor light: (receiver, light, start, unit direction, length).

    Starts, directions and lengths come as the float32 the tracer takes; a ray stops ``short`` of the
    light (at least 0.1 mm long).
    """
    m, nl = e.shape
    keep = np.zeros((m, nl), dtype=np.bool_)
    count = 0
    for i in range(m):
        total = 0.0
        for j in range(nl):
            total += e[i, j]
        for j in range(nl):
            if e[i, j] > 0.0 and e[i, j] >= minor * total:
                keep[i, j] = True
                count += 1
    tex = np.empty(count, dtype=np.int64)
    light = np.empty(count, dtype=np.int64)
    starts = np.empty((count, 3), dtype=np.float32)
    dirs = np.empty((count, 3), dtype=np.float32)
    reach = np.empty(count, dtype=np.float32)
    k = 0
    for i in range(m):
        for j in range(nl):
            if not keep[i, j]:
                continue
            px, py, pz = _light_point(j, i * 7 + j, kind, centre, u, v, half, radius)
            dx, dy, dz = px - origin[i, 0], py - origin[i, 1], pz - origin[i, 2]
            d = max(math.sqrt(dx * dx + dy * dy + dz * dz), 1e-12)
            tex[k], light[k] = i, j
            starts[k, 0], starts[k, 1], starts[k, 2] = origin[i, 0], origin[i, 1], origin[i, 2]
            dirs[k, 0], dirs[k, 1], dirs[k, 2] = dx / d, dy / d, dz / d
            reach[k] = max(d - short, 1e-4)
            k += 1
    return tex, light, starts, dirs, reach


def _gather(coarse, fine, fine_direct, fine_albedo, tracer) -> np.ndarray:
    """(C, 3) indirect irradiance at the coarse texels after :data:`BOUNCES` bounces."""
    k = len(coarse.keys)
    dirs_local = _hemisphere(GATHER_RAYS)
    t1, t2 = _frames(coarse.normal)
    # a different turn of the pattern per texel: neighbours sample different directions
    turn = (np.arange(k) * 0.61803398875 % 1.0) * 2 * math.pi
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    dx, dy, dz = dirs_local[None, :, 0], dirs_local[None, :, 1], dirs_local[None, :, 2]
    rx, ry = c * dx - s * dy, s * dx + c * dy
    dirs = rx[..., None] * t1[:, None] + ry[..., None] * t2[:, None] + dz[..., None] * coarse.normal[:, None]
    dirs = dirs.reshape(-1, 3)
    origin = np.repeat(coarse.pos + coarse.normal * RAY_OFFSET_M, GATHER_RAYS, axis=0)
    hit_fine = _hit_texels(origin, dirs, fine, coarse, tracer)
    owner = np.repeat(np.arange(k), GATHER_RAYS)
    return _iterate(owner, hit_fine, k, fine_direct, fine_albedo, coarse.index, GATHER_RAYS)


def _hit_texels(origin, dirs, fine: Texels, coarse: Texels, tracer: Tracer) -> np.ndarray:
    """The fine texel each ray hits (−1: it escapes, or hits a surface without surfels around).

    The texel of the hit's cell and face orientation; where that cell has no surfels (a proxy face the
    Gaussians skip, a cell boundary), the largest fine texel of the coarse texel there.
    """
    t, hit, ng = tracer.intersect(origin, dirs)
    point = origin + dirs * np.where(hit, t, 0.0)[:, None]
    bucket = buckets(ng)
    found = fine.lookup(point + ng * 0.004, bucket)
    found = np.where(found < 0, fine.lookup(point - ng * 0.004, bucket), found)
    missing = np.flatnonzero(hit & (found < 0))
    if len(missing):
        largest = np.full(len(coarse.keys), -1)
        order = np.argsort(fine.count, kind="stable")
        largest[coarse.index[order]] = order  # the last write per coarse texel is its largest fine texel
        for sign in (1.0, -1.0):
            ck = coarse.lookup(point[missing] + sign * ng[missing] * 0.004, bucket[missing])
            found[missing] = np.where((found[missing] < 0) & (ck >= 0), largest[np.maximum(ck, 0)], found[missing])
    return np.where(hit, found, -1)


def _iterate(owner, hit_fine, k, fine_direct, fine_albedo, parent, rays_per) -> np.ndarray:
    """Bounce iterations of the gather: E_ind = mean over rays of ρ_hit (E_direct,hit + E_ind,parent(hit)).

    The rays are a sparse (coarse texel × fine texel) matrix, so a bounce is one product; iterated
    until a bounce adds under :data:`BOUNCE_TOLERANCE` of the indirect light (at most :data:`BOUNCES`).
    """
    from scipy.sparse import csr_matrix

    valid = hit_fine >= 0
    gather = csr_matrix(
        (np.full(int(valid.sum()), 1.0 / rays_per), (owner[valid], hit_fine[valid])), shape=(k, len(fine_direct))
    )
    indirect = np.zeros((k, 3))
    for _ in range(BOUNCES):
        radiance = fine_albedo * (fine_direct + indirect[parent])
        new = gather @ radiance
        change = float(np.abs(new - indirect).sum()) / max(float(new.sum()), 1e-30)
        indirect = new
        if change < BOUNCE_TOLERANCE:
            break
    return indirect


def _probes(floor, table, tracer, fine, coarse, fine_direct, fine_albedo, indirect_coarse, exposure) -> ProbeGrid:
    grid, floor_mask = floor
    parent = coarse.index
    x0, y0 = grid.origin
    rows_m, cols_m = grid.shape[0] * grid.resolution, grid.shape[1] * grid.resolution
    gx = np.arange(x0, x0 + cols_m + 1e-9, PROBE_SPACING_M)
    gy = np.arange(y0, y0 + rows_m + 1e-9, PROBE_SPACING_M)
    xx, yy = np.meshgrid(gx, gy)
    xy = np.column_stack([xx.ravel(), yy.ravel()])
    rc = grid.to_cell(xy)
    inside = (rc[:, 0] >= 0) & (rc[:, 0] < grid.shape[0]) & (rc[:, 1] >= 0) & (rc[:, 1] < grid.shape[1])
    ok = np.zeros(len(xy), bool)
    ok[inside] = floor_mask[rc[inside, 0], rc[inside, 1]]
    pts = np.column_stack([xy[ok], np.full(ok.sum(), PROBE_HEIGHT_M)])
    m = len(pts)
    values = np.zeros((len(xy), 3))
    if m:
        direct = np.zeros((m, 3))
        if len(table):
            e = np.zeros((m, len(table)))
            for axis in _AXES:
                e += _per_light(pts, np.tile(axis, (m, 1)), table.kind, table.centre, table.u, table.v, table.n,
                                table.half, table.scale, table.radius) / 6  # fmt: skip
            p, light, starts, dirs_l, reach = _shadow_rays(pts, e, 0.0, 0.01, table.kind, table.centre, table.u,
                                                           table.v, table.half, table.radius)  # fmt: skip
            blocked = tracer.occluded(starts, dirs_l, reach)
            w = e[p, light][:, None] * table.colour[light] * ~blocked[:, None]
            direct = sum_by(p, w, m)
        dirs = np.tile(_sphere(PROBE_RAYS), (m, 1))
        origin = np.repeat(pts, PROBE_RAYS, axis=0)
        hit_fine = _hit_texels(origin, dirs, fine, coarse, tracer)
        valid = hit_fine >= 0
        h = hit_fine[valid]
        radiance = fine_albedo[h] * (fine_direct[h] + indirect_coarse[parent[h]]) / math.pi
        owner = np.repeat(np.arange(m), PROBE_RAYS)[valid]
        mean_l = sum_by(owner, radiance, m) / PROBE_RAYS
        values[ok] = direct + math.pi * mean_l
    values = values.reshape(len(gy), len(gx), 3)
    if ok.any() and not ok.all():  # off-floor probes take their nearest floor probe's value
        from scipy.ndimage import distance_transform_edt

        _, (ri, ci) = distance_transform_edt(~ok.reshape(len(gy), len(gx)), return_indices=True)
        values = values[ri, ci]
    return ProbeGrid((float(gx[0]), float(gy[0])), PROBE_SPACING_M, values.astype(np.float32), float(exposure))


def probe_irradiance(probes: ProbeGrid, xy: np.ndarray) -> np.ndarray:
    """Bilinearly interpolated probe irradiance (M, 3) at points ``xy`` (M, 2) (clamped to the grid)."""
    rows, cols = probes.values.shape[:2]
    f = (np.asarray(xy, dtype=np.float64) - np.asarray(probes.origin)) / probes.spacing
    fx = np.clip(f[:, 0], 0, cols - 1)
    fy = np.clip(f[:, 1], 0, rows - 1)
    x0, y0 = (
        np.minimum(np.floor(fx).astype(int), cols - 2 if cols > 1 else 0),
        np.minimum(np.floor(fy).astype(int), rows - 2 if rows > 1 else 0),
    )
    x1, y1 = np.minimum(x0 + 1, cols - 1), np.minimum(y0 + 1, rows - 1)
    tx, ty = (fx - x0)[:, None], (fy - y0)[:, None]
    v = probes.values.astype(np.float64)
    return (v[y0, x0] * (1 - tx) + v[y0, x1] * tx) * (1 - ty) + (v[y1, x0] * (1 - tx) + v[y1, x1] * tx) * ty
