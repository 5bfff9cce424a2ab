"""Exact planar depth of triangle meshes (a scene's USD proxy) by z-buffering: the geometric ground truth.

The Gaussian renderer approximates surfaces; this draws the proxy's triangles themselves, so tests can
measure how far the rendered depth of a scene's Gaussians is from the surfaces they stand for, and a
caller can get a noiseless depth image of the proxy. Triangles are clipped against the near plane
(Sutherland–Hodgman), projected with the camera's intrinsics and filled at pixel centres (the same
(j + ½, i + ½) convention as the splat renderer); depth is 1/z interpolated linearly in screen space,
which is exact for planar triangles. Written as a small numba kernel because no maintained library
rasterizes depth on the CPU without an OpenGL context.
"""

from __future__ import annotations

import numba
import numpy as np

from song.render.camera import Camera


@numba.njit(cache=True)
def _fill(a, b, c, fx, fy, cx, cy, out) -> None:  # pragma: no cover - compiled
    """Fill one triangle (camera coordinates, all in front of the near plane) into the z-buffer."""
    h, w = out.shape
    ua, va, ia = fx * a[0] / a[2] + cx, fy * a[1] / a[2] + cy, 1.0 / a[2]
    ub, vb, ib = fx * b[0] / b[2] + cx, fy * b[1] / b[2] + cy, 1.0 / b[2]
    uc, vc, ic = fx * c[0] / c[2] + cx, fy * c[1] / c[2] + cy, 1.0 / c[2]
    area = (ub - ua) * (vc - va) - (vb - va) * (uc - ua)
    if abs(area) < 1e-12:
        return
    j0 = max(0, int(np.floor(min(ua, ub, uc) - 0.5)))
    j1 = min(w - 1, int(np.ceil(max(ua, ub, uc) - 0.5)))
    i0 = max(0, int(np.floor(min(va, vb, vc) - 0.5)))
    i1 = min(h - 1, int(np.ceil(max(va, vb, vc) - 0.5)))
    for i in range(i0, i1 + 1):
        py = i + 0.5
        for j in range(j0, j1 + 1):
            px = j + 0.5
            wa = ((ub - px) * (vc - py) - (vb - py) * (uc - px)) / area
            wb = ((uc - px) * (va - py) - (vc - py) * (ua - px)) / area
            wc = 1.0 - wa - wb
            if wa < 0.0 or wb < 0.0 or wc < 0.0:
                continue
            z = 1.0 / (wa * ia + wb * ib + wc * ic)
            if z < out[i, j]:
                out[i, j] = z


@numba.njit(cache=True)
def _zbuffer(tris, fx, fy, cx, cy, near, out) -> None:  # pragma: no cover - compiled
    """Clip every triangle (T, 3, 3) of camera coordinates at z = near and fill the pieces."""
    poly = np.empty((4, 3))
    for t in range(tris.shape[0]):
        n = 0
        for k in range(3):
            p, q = tris[t, k], tris[t, (k + 1) % 3]
            if p[2] >= near:
                poly[n] = p
                n += 1
            if (p[2] >= near) != (q[2] >= near):
                s = (near - p[2]) / (q[2] - p[2])
                poly[n] = p + s * (q - p)
                n += 1
        for k in range(1, n - 1):
            _fill(poly[0], poly[k], poly[k + 1], fx, fy, cx, cy, out)


def mesh_depth(meshes, camera: Camera) -> np.ndarray:
    """(H, W) float32 planar depth z of the nearest triangle at every pixel centre; +inf where none.

    Args:
        meshes: objects with ``vertices`` (V, 3) and ``faces`` (F, 3) (e.g.
            :class:`~song.datasets.scenes.usd.ProxyMesh`), world metres.
        camera: the view.
    """
    tris = [np.asarray(m.vertices, dtype=np.float64)[np.asarray(m.faces)] for m in meshes if len(m.faces)]
    out = np.full((camera.height, camera.width), np.inf)
    if tris:
        cam = camera.to_camera(np.concatenate(tris))
        _zbuffer(np.ascontiguousarray(cam), camera.fx, camera.fy, camera.cx, camera.cy, camera.near, out)
    return out.astype(np.float32)
