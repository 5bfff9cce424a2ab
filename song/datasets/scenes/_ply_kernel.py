"""Compiled SuperSplat packing: a chunk's ranges -> the four packed words of each splat.

One pass per splat in place of numpy's dozen full-array passes (~0.6 s per million splats to ~0.03). The
plain numpy twin is :func:`song.datasets.scenes.ply.pack_vertices_reference`; the two give the same
bytes (tests/datasets/scenes/test_ply.py). Every step is the twin's float64 arithmetic in its order, and
everything whose rounding numpy might do differently (the quaternions' norm, the sigmoid) is computed by
the caller in numpy and passed in.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def _fraction(value, lo, hi, min_span):  # pragma: no cover
    """SuperSplat's normalise (the twin's ``_fraction``)."""
    span = hi - lo
    t = (value - lo) / (1.0 if span < min_span else span)
    if span < min_span:
        t = 0.0
    if value <= lo:
        return 0.0
    if value >= hi:
        return 1.0
    return t


@nb.njit(cache=True, inline="always")
def _unorm(t, bits):  # pragma: no cover
    top = (1 << bits) - 1
    v = np.floor(t * top + 0.5)
    if v < 0.0:
        v = 0.0
    if v > top:
        v = float(top)
    return np.uint32(v)


@nb.njit(cache=True, inline="always")
def _p111011(values, i, lo, hi, c, min_span):  # pragma: no cover
    x = _unorm(_fraction(values[i, 0], lo[c, 0], hi[c, 0], min_span), 11)
    y = _unorm(_fraction(values[i, 1], lo[c, 1], hi[c, 1], min_span), 10)
    z = _unorm(_fraction(values[i, 2], lo[c, 2], hi[c, 2], min_span), 11)
    return (x << np.uint32(21)) | (y << np.uint32(11)) | z


@nb.njit(cache=True, nogil=True)
def pack_vertices(
    means,
    pos_lo,
    pos_hi,
    log_scales,
    scale_lo,
    scale_hi,
    colours,
    colour_lo,
    colour_hi,
    opacity,
    quats,
    chunk,
    min_span,
    sqrt1_2,
):  # pragma: no cover
    """(position, rotation, scale, colour) words (N,) uint32 each.

    ``*_lo``/``*_hi`` (chunks, 3) are the ranges as stored (float32, widened); ``colours`` 0.5 + C0·DC;
    ``opacity`` the sigmoid of the logits; ``quats`` (N, 4) unit quaternions (w, x, y, z).
    """
    n = len(means)
    position = np.empty(n, np.uint32)
    rotation = np.empty(n, np.uint32)
    scale = np.empty(n, np.uint32)
    colour = np.empty(n, np.uint32)
    for i in range(n):
        c = i // chunk
        position[i] = _p111011(means, i, pos_lo, pos_hi, c, min_span)
        scale[i] = _p111011(log_scales, i, scale_lo, scale_hi, c, min_span)
        r = _unorm(_fraction(colours[i, 0], colour_lo[c, 0], colour_hi[c, 0], min_span), 8)
        g = _unorm(_fraction(colours[i, 1], colour_lo[c, 1], colour_hi[c, 1], min_span), 8)
        b = _unorm(_fraction(colours[i, 2], colour_lo[c, 2], colour_hi[c, 2], min_span), 8)
        a = _unorm(opacity[i], 8)
        colour[i] = (r << np.uint32(24)) | (g << np.uint32(16)) | (b << np.uint32(8)) | a
        largest = 0  # the first of equal magnitudes, as np.argmax
        for k in range(1, 4):
            if abs(quats[i, k]) > abs(quats[i, largest]):
                largest = k
        sign = -1.0 if quats[i, largest] < 0 else 1.0
        word = np.uint32(largest) << np.uint32(30)
        shift = 20
        for k in range(4):
            if k != largest:
                word |= _unorm(quats[i, k] * sign * sqrt1_2 + 0.5, 10) << np.uint32(shift)
                shift -= 10
        rotation[i] = word
    return position, rotation, scale, colour


@nb.njit(cache=True)
def turn_quats(turn, quats):  # pragma: no cover - compiled; twin: song.geometry.rotations.quat_mul (tested)
    """``turn ⊗ q`` for every row of ``quats`` (N, 4) float32, in float64 as ``quat_mul``, rounded to float32."""
    aw, ax, ay, az = turn[0], turn[1], turn[2], turn[3]
    out = np.empty(quats.shape, dtype=np.float32)
    for i in range(quats.shape[0]):
        bw, bx, by, bz = (
            np.float64(quats[i, 0]),
            np.float64(quats[i, 1]),
            np.float64(quats[i, 2]),
            np.float64(quats[i, 3]),
        )
        out[i, 0] = aw * bw - ax * bx - ay * by - az * bz
        out[i, 1] = aw * bx + ax * bw + ay * bz - az * by
        out[i, 2] = aw * by - ax * bz + ay * bw + az * bx
        out[i, 3] = aw * bz + ax * by - ay * bx + az * bw
    return out
