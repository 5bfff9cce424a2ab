"""Compiled (numba) tile rasterizer of 3D Gaussian splats, with gsplat's conventions (3DGS, Kerbl et al. 2023).

Three passes, each a loop that numpy cannot express without (N × pixels) temporaries -- which is why
this is numba and not numpy:

1. :func:`project_kernel` (parallel over Gaussians): camera transform, near/far cull, 3-D covariance
   from rotation and scale, EWA projection with the Jacobian clamped to 1.3× the field of view,
   covariance dilation by ``eps2d`` (0.3 px²), conic, opacity cull below 1/255, the opacity-aware tight
   box (extent min(3.33, √(2 ln(255·o))) σ per axis: exactly where α ≥ 1/255), image cull, colour from
   SH (degree ≤ 3, + 0.5, clamped at 0) along the view direction, and the tile rectangle.
2. :func:`depth_order` (a parallel stable radix sort of the depths), then :func:`bin_kernel`: every
   visible Gaussian, already in depth order, appended to the list of each
   16×16 tile its box touches (count, prefix sum, fill), so each tile's list is front to back.
3. :func:`composite_kernel` (parallel over tiles): per pixel centre, front to back,
   α = min(0.999, o·exp(−σ)) skipped when σ < 0 or α < 1/255; stop (exclusive) once the transmittance
   would fall to 1e-4 or below; colour, depth z and alpha accumulated with weights α·T.

Every pixel is computed by exactly one thread from the same ordered list, so images do not depend on
the thread count. ``_render_reference.py`` is the per-pixel numpy twin.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

TILE = 16
ALPHA_MIN = 1.0 / 255.0  # contributions below this are skipped (gsplat ALPHA_THRESHOLD)
ALPHA_MAX = 0.999  # per-Gaussian alpha cap (gsplat; the original 3DGS code uses 0.99)
T_MIN = 1e-4  # a pixel stops once its transmittance would fall to this or below
EXTEND_MAX = 3.33  # box half-size in σ for an opaque Gaussian: √(2 ln 255)
CUT_GUARD = 1e-6  # slack on the σ cut so that only the exact α ≥ 1/255 test decides at the boundary
FOV_CLAMP = 0.3  # the Jacobian's x/z, y/z are clamped to the image half-extent + 30 % of tan(fov/2)

# one row per projected Gaussian (contiguous, so compositing reads one or two cache lines per splat)
U, V, CA, CB, CC, OPAC, R, G, B, Z, BX, BY, CUT = range(13)
N_ATTR = 13

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)


LOG2E = 1.4426950408889634
LN2 = 0.6931471805599453
POW2_NEG = np.array([2.0**-k for k in range(64)])  # 2^-k; k ≤ 9 here (σ ≤ ln 255 + guard)


@numba.njit(cache=True, inline="always")
def exp_neg(sigma):
    """e^(−σ) for 0 ≤ σ < 40, relative error < 1e-8.

    libm's ``exp`` took half of the compositing time; here σ·log₂e is split into its nearest integer k
    (a table of 2^−k) and a remainder |x| ≤ ln2/2, whose e^(−x) is a degree-7 Taylor polynomial
    (truncation (ln2/2)^8 / 8! < 6e-9).
    """
    y = sigma * LOG2E
    k = int(y + 0.5)
    x = (y - k) * LN2
    p = 1.0 - x * (
        1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0 - x * (1.0 / 720.0 - x / 5040.0)))))
    )
    return p * POW2_NEG[k]


@numba.njit(cache=True, inline="always")
def _sh_colour(sh, i, c, degree, x, y, z):
    """Channel ``c`` of Gaussian ``i``'s SH colour along the unit direction (x, y, z), before the +0.5."""
    r = C0 * sh[i, 0, c]
    if degree > 0:
        r += -C1 * y * sh[i, 1, c] + C1 * z * sh[i, 2, c] - C1 * x * sh[i, 3, c]
        if degree > 1:
            xx, yy, zz = x * x, y * y, z * z
            r += (
                C2[0] * x * y * sh[i, 4, c]
                + C2[1] * y * z * sh[i, 5, c]
                + C2[2] * (2.0 * zz - xx - yy) * sh[i, 6, c]
                + C2[3] * x * z * sh[i, 7, c]
                + C2[4] * (xx - yy) * sh[i, 8, c]
            )
            if degree > 2:
                r += (
                    C3[0] * y * (3.0 * xx - yy) * sh[i, 9, c]
                    + C3[1] * x * y * z * sh[i, 10, c]
                    + C3[2] * y * (4.0 * zz - xx - yy) * sh[i, 11, c]
                    + C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh[i, 12, c]
                    + C3[4] * x * (4.0 * zz - xx - yy) * sh[i, 13, c]
                    + C3[5] * z * (xx - yy) * sh[i, 14, c]
                    + C3[6] * x * (xx - 3.0 * yy) * sh[i, 15, c]
                )
    return r


@numba.njit(cache=True, parallel=True, fastmath=True)
def project_kernel(means, quats, scales, opacities, log_alpha, sh, degree, sel, rot, trans, campos,
                   fx, fy, cx, cy, width, height, near, far, eps2d, offset, row0, attr, depth, rect, valid):  # fmt: skip
    """Project Gaussians ``sel`` of one set into rows ``offset + k`` of ``attr`` (N, N_ATTR), ``depth``, ``rect``.

    ``log_alpha`` is ln(255·opacity) per Gaussian (:meth:`GaussianSet.log_alpha_range`, computed once per
    set): the σ beyond which α < 1/255. ``row0`` is added to the tile rows of ``rect``: camera b of a batch
    owns tile rows b·tiles_y … (b + 1)·tiles_y − 1, so one binning serves every camera.
    """
    tiles_x = (width + TILE - 1) // TILE
    tiles_y = (height + TILE - 1) // TILE
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lim_xp, lim_xn = (width - cx) / fx + FOV_CLAMP * tan_x, cx / fx + FOV_CLAMP * tan_x
    lim_yp, lim_yn = (height - cy) / fy + FOV_CLAMP * tan_y, cy / fy + FOV_CLAMP * tan_y
    for k in prange(sel.shape[0]):
        i = sel[k]
        o = offset + k
        valid[o] = False
        px, py, pz = float(means[i, 0]), float(means[i, 1]), float(means[i, 2])
        x = rot[0, 0] * px + rot[0, 1] * py + rot[0, 2] * pz + trans[0]
        y = rot[1, 0] * px + rot[1, 1] * py + rot[1, 2] * pz + trans[1]
        z = rot[2, 0] * px + rot[2, 1] * py + rot[2, 2] * pz + trans[2]
        if z < near or z > far:
            continue
        # world covariance Σ = M Mᵀ with M = R(q) diag(s)
        qw, qx, qy, qz = float(quats[i, 0]), float(quats[i, 1]), float(quats[i, 2]), float(quats[i, 3])
        n = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if n == 0.0:
            continue
        qw, qx, qy, qz = qw / n, qx / n, qy / n, qz / n
        sx, sy, sz = float(scales[i, 0]), float(scales[i, 1]), float(scales[i, 2])
        m00 = (1.0 - 2.0 * (qy * qy + qz * qz)) * sx
        m01 = 2.0 * (qx * qy - qw * qz) * sy
        m02 = 2.0 * (qx * qz + qw * qy) * sz
        m10 = 2.0 * (qx * qy + qw * qz) * sx
        m11 = (1.0 - 2.0 * (qx * qx + qz * qz)) * sy
        m12 = 2.0 * (qy * qz - qw * qx) * sz
        m20 = 2.0 * (qx * qz - qw * qy) * sx
        m21 = 2.0 * (qy * qz + qw * qx) * sy
        m22 = (1.0 - 2.0 * (qx * qx + qy * qy)) * sz
        # camera-frame M: rot @ M
        a0 = rot[0, 0] * m00 + rot[0, 1] * m10 + rot[0, 2] * m20
        a1 = rot[0, 0] * m01 + rot[0, 1] * m11 + rot[0, 2] * m21
        a2 = rot[0, 0] * m02 + rot[0, 1] * m12 + rot[0, 2] * m22
        b0 = rot[1, 0] * m00 + rot[1, 1] * m10 + rot[1, 2] * m20
        b1 = rot[1, 0] * m01 + rot[1, 1] * m11 + rot[1, 2] * m21
        b2 = rot[1, 0] * m02 + rot[1, 1] * m12 + rot[1, 2] * m22
        c0 = rot[2, 0] * m00 + rot[2, 1] * m10 + rot[2, 2] * m20
        c1 = rot[2, 0] * m01 + rot[2, 1] * m11 + rot[2, 2] * m21
        c2 = rot[2, 0] * m02 + rot[2, 1] * m12 + rot[2, 2] * m22
        # EWA: J (2×3) with x/z, y/z clamped; T = J @ (rot M); cov2d = T Tᵀ
        rz = 1.0 / z
        tx = z * min(lim_xp, max(-lim_xn, x * rz))
        ty = z * min(lim_yp, max(-lim_yn, y * rz))
        j00, j02 = fx * rz, -fx * tx * rz * rz
        j11, j12 = fy * rz, -fy * ty * rz * rz
        t00, t01, t02 = j00 * a0 + j02 * c0, j00 * a1 + j02 * c1, j00 * a2 + j02 * c2
        t10, t11, t12 = j11 * b0 + j12 * c0, j11 * b1 + j12 * c1, j11 * b2 + j12 * c2
        cxx = t00 * t00 + t01 * t01 + t02 * t02 + eps2d
        cxy = t00 * t10 + t01 * t11 + t02 * t12
        cyy = t10 * t10 + t11 * t11 + t12 * t12 + eps2d
        det = cxx * cyy - cxy * cxy
        if det <= 0.0:
            continue
        o_i = float(opacities[i])
        if o_i < ALPHA_MIN:
            continue
        cut = float(log_alpha[i])
        extend = min(EXTEND_MAX, math.sqrt(2.0 * cut))
        b = 0.5 * (cxx + cyy)
        r1 = extend * math.sqrt(b + math.sqrt(max(0.01, b * b - det)))
        rx = math.ceil(min(extend * math.sqrt(cxx), r1))
        ry = math.ceil(min(extend * math.sqrt(cyy), r1))
        if rx <= 0.0 and ry <= 0.0:
            continue
        u = fx * x * rz + cx
        v = fy * y * rz + cy
        if u + rx <= 0.0 or u - rx >= width or v + ry <= 0.0 or v - ry >= height:
            continue
        attr[o, U], attr[o, V] = u, v
        attr[o, CA], attr[o, CB], attr[o, CC] = cyy / det, -cxy / det, cxx / det
        attr[o, OPAC] = o_i
        attr[o, Z] = z
        attr[o, BX], attr[o, BY] = rx, ry
        # α < 1/255 ⟺ σ > ln(255·o); the guard keeps rounding on the safe side (the α test decides)
        attr[o, CUT] = cut + CUT_GUARD
        depth[o] = z
        if degree == 0:  # view-independent colour: no direction needed
            for c in range(3):
                attr[o, R + c] = max(C0 * sh[i, 0, c] + 0.5, 0.0)
        else:
            dx, dy, dz = px - campos[0], py - campos[1], pz - campos[2]
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dn > 0.0:
                dx, dy, dz = dx / dn, dy / dn, dz / dn
            for c in range(3):
                attr[o, R + c] = max(_sh_colour(sh, i, c, degree, dx, dy, dz) + 0.5, 0.0)
        # tiles holding a pixel centre within the box: columns u − rx − ½ … u + rx − ½ (a superset)
        rect[o, 0] = min(max(0, int(math.floor((u - rx - 0.5) / TILE))), tiles_x)
        rect[o, 1] = min(max(0, int(math.floor((u + rx - 0.5) / TILE)) + 1), tiles_x)
        rect[o, 2] = min(max(0, int(math.floor((v - ry - 0.5) / TILE))), tiles_y) + row0
        rect[o, 3] = min(max(0, int(math.floor((v + ry - 0.5) / TILE)) + 1), tiles_y) + row0
        valid[o] = rect[o, 1] > rect[o, 0] and rect[o, 3] > rect[o, 2]


RADIX_BITS = 11  # three passes cover a float32's 31 magnitude bits; 2,048 buckets a pass stay in cache


@numba.njit(cache=True, parallel=True)
def depth_order(index, depth, n_parts):
    """``index`` sorted by ``depth[index]`` (positive float32 depths), stable: a 3 × 11-bit LSD radix sort.

    Ties keep the input order, as gsplat's stable radix sort of its depth keys does. Each pass is a
    parallel counting sort (as in :func:`bin_kernel`): part k counts its contiguous slice, a prefix sum
    over (bucket, part) places every part in every bucket, and each part scatters its slice in order; a
    stable order is unique, so the result does not depend on ``n_parts`` or the thread count.
    """
    n = index.shape[0]
    keys = np.empty(n, dtype=np.uint32)
    for k in prange(n):
        keys[k] = np.float32(depth[index[k]]).view(np.uint32)  # positive floats order as their bits
    src_i, src_k = index.copy(), keys
    dst_i, dst_k = np.empty_like(src_i), np.empty_like(keys)
    bounds = np.linspace(0, n, n_parts + 1).astype(np.int64)
    buckets = 1 << RADIX_BITS
    mask = np.uint32(buckets - 1)
    for shift in range(0, 32, RADIX_BITS):
        place = np.zeros((n_parts, buckets), dtype=np.int64)
        for p in prange(n_parts):
            for k in range(bounds[p], bounds[p + 1]):
                place[p, (src_k[k] >> shift) & mask] += 1
        running = 0
        for b in range(buckets):
            for p in range(n_parts):
                count = place[p, b]
                place[p, b] = running
                running += count
        for p in prange(n_parts):
            fill = place[p]
            for k in range(bounds[p], bounds[p + 1]):
                b = (src_k[k] >> shift) & mask
                dst_i[fill[b]] = src_i[k]
                dst_k[fill[b]] = src_k[k]
                fill[b] += 1
        src_i, dst_i = dst_i, src_i
        src_k, dst_k = dst_k, src_k
    return src_i


@numba.njit(cache=True, parallel=True)
def bin_kernel(order, rect, tiles_x, tiles_y, n_parts):
    """Tile lists front to back: ``(offsets (T + 1,), ids (E,) int32)``; ``order`` lists the visible Gaussians by depth.

    A parallel counting sort: part k counts the tiles of its contiguous slice of ``order``, a prefix
    sum over (tile, part) gives every part its place in every tile's list, and each part then fills its
    places in slice order -- so every list keeps the depth order whatever the number of threads.
    """
    n_tiles = tiles_x * tiles_y
    n = order.shape[0]
    bounds = np.linspace(0, n, n_parts + 1).astype(np.int64)
    sorted_rect = np.empty((n, 4), dtype=np.int32)  # one gather, then both passes read sequentially
    for q in prange(n):
        for c in range(4):
            sorted_rect[q, c] = rect[order[q], c]
    counts = np.zeros((n_parts, n_tiles), dtype=np.int64)
    for k in prange(n_parts):
        for q in range(bounds[k], bounds[k + 1]):
            for ty in range(sorted_rect[q, 2], sorted_rect[q, 3]):
                for tx in range(sorted_rect[q, 0], sorted_rect[q, 1]):
                    counts[k, ty * tiles_x + tx] += 1
    offsets = np.zeros(n_tiles + 1, dtype=np.int64)
    start = np.zeros((n_parts, n_tiles), dtype=np.int64)
    running = 0
    for t in range(n_tiles):
        offsets[t] = running
        for k in range(n_parts):
            start[k, t] = running
            running += counts[k, t]
    offsets[n_tiles] = running
    ids = np.empty(running, dtype=np.int32)  # row ids: half the bytes the compositing reads per entry
    for k in prange(n_parts):
        fill = start[k]
        for q in range(bounds[k], bounds[k + 1]):
            g = order[q]
            for ty in range(sorted_rect[q, 2], sorted_rect[q, 3]):
                for tx in range(sorted_rect[q, 0], sorted_rect[q, 1]):
                    t = ty * tiles_x + tx
                    ids[fill[t]] = g
                    fill[t] += 1
    return offsets, ids


@numba.njit(cache=True, parallel=True, fastmath=True)
def composite_kernel(offsets, ids, attr, width, height, tiles_x, tiles_y, background, out_rgb, out_depth, out_alpha):
    """Front-to-back compositing of every pixel (see module doc); outputs float32 (B, H, W, 3), (B, H, W), (B, H, W).

    Tile ``t`` is tile ``t mod (tiles_x·tiles_y)`` of camera ``t div (tiles_x·tiles_y)``: the cameras of a
    batch are composited in one parallel loop, each pixel exactly as if its camera were rendered alone.

    Within a tile the loop runs Gaussian by Gaussian over the pixels of its box that are not finished
    (outside the box α < 1/255, so such pixels would skip it anyway): each pixel sees the same Gaussians
    in the same order as a per-pixel loop, with the work proportional to the boxes' areas. Finished
    pixels are kept as one bit mask per tile row, so a row of the box that is already finished costs one
    test; α < 1/255 is tested as σ > ln(255·o) first, which spares the exponential for the tails.
    """
    n_tiles = offsets.shape[0] - 1
    per_camera = tiles_x * tiles_y
    rows = n_tiles // tiles_x
    evens = (rows + 1) // 2
    for q in prange(n_tiles):
        # even tile rows first, then odd ones: the threads' contiguous shares of the loop each hold rows
        # from the whole image (a top half of ceiling and a bottom half of floor and people cost unequally)
        k, col = q // tiles_x, q % tiles_x
        t = (2 * k if k < evens else 2 * (k - evens) + 1) * tiles_x + col
        cam, local = t // per_camera, t % per_camera
        x0 = (local % tiles_x) * TILE
        y0 = (local // tiles_x) * TILE
        nx = min(TILE, width - x0)
        ny = min(TILE, height - y0)
        trans = np.ones(TILE * TILE)
        acc = np.zeros((TILE * TILE, 4))
        done = np.zeros(TILE, dtype=np.uint32)  # bit j of row i: pixel (i, j) is finished
        full = np.uint32((1 << nx) - 1)
        rows_left = ny
        for e in range(offsets[t], offsets[t + 1]):
            a = attr[ids[e]]
            u, v = a[U], a[V]
            c0 = max(0, int(math.floor(u - a[BX] - 0.5)) - x0)
            c1 = min(nx, int(math.ceil(u + a[BX] + 0.5)) - x0)
            r0 = max(0, int(math.floor(v - a[BY] - 0.5)) - y0)
            r1 = min(ny, int(math.ceil(v + a[BY] + 0.5)) - y0)
            if c1 <= c0:
                continue
            span = np.uint32(((1 << c1) - 1) ^ ((1 << c0) - 1))
            ca, cb, cc, o, cut = a[CA], a[CB], a[CC], a[OPAC], a[CUT]
            # the pixels of a row with σ ≤ cut: σ(dx) = ½·ca·dx² + cb·dy·dx + ½·cc·dy² (dx = u − px, ca > 0),
            # i.e. dx ∈ (−cb·dy ± √(dy²·(cb² − ca·cc) + 2·ca·cut)) / ca
            k1, k2, inv_ca = cb * cb - ca * cc, 2.0 * ca * cut, 1.0 / ca
            for i in range(r0, r1):
                if done[i] & span == span:
                    continue
                dy = v - (y0 + i + 0.5)
                disc = dy * dy * k1 + k2
                if disc < 0.0:
                    continue
                mid = u + cb * dy * inv_ca - x0 - 0.5  # column of the row's σ minimum
                half = math.sqrt(disc) * inv_ca
                j0 = max(c0, int(math.floor(mid - half)))  # the σ test below decides at the ends
                j1 = min(c1, int(math.ceil(mid + half)) + 1)
                row = i * TILE
                for j in range(j0, j1):
                    if done[i] >> j & 1:
                        continue
                    dx = u - (x0 + j + 0.5)
                    sigma = 0.5 * (ca * dx * dx + cc * dy * dy) + cb * dx * dy
                    if sigma < 0.0 or sigma > cut:
                        continue
                    alpha = min(ALPHA_MAX, o * exp_neg(sigma))
                    if alpha < ALPHA_MIN:
                        continue
                    p = row + j
                    tp = trans[p]
                    next_t = tp * (1.0 - alpha)
                    if next_t <= T_MIN:
                        done[i] |= np.uint32(1 << j)
                        if done[i] == full:
                            rows_left -= 1
                        continue
                    w = alpha * tp
                    acc[p, 0] += a[R] * w
                    acc[p, 1] += a[G] * w
                    acc[p, 2] += a[B] * w
                    acc[p, 3] += a[Z] * w
                    trans[p] = next_t
            if rows_left == 0:
                break
        for i in range(ny):
            for j in range(nx):
                p = i * TILE + j
                tr = trans[p]
                al = 1.0 - tr
                out_rgb[cam, y0 + i, x0 + j, 0] = acc[p, 0] + tr * background[0]
                out_rgb[cam, y0 + i, x0 + j, 1] = acc[p, 1] + tr * background[1]
                out_rgb[cam, y0 + i, x0 + j, 2] = acc[p, 2] + tr * background[2]
                out_alpha[cam, y0 + i, x0 + j] = al
                out_depth[cam, y0 + i, x0 + j] = acc[p, 3] / al if al > 0.0 else 0.0
