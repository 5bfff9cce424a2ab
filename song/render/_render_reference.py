"""Plain numpy twin of the tile rasterizer: per-pixel compositing over every Gaussian, for tiny images.

Same definition as :mod:`song.render._render_kernel` (gsplat's conventions), written the obvious way:
project all Gaussians with array maths, sort them by depth, then for each pixel walk the whole sorted
list. No tiles, no boxes beyond the opacity-aware cut -- so tests can compare the fast path's culling,
binning and early exits against it.
"""

from __future__ import annotations

import numpy as np

from song.render._render_kernel import (
    ALPHA_MAX,
    ALPHA_MIN,
    C0,
    C1,
    C2,
    C3,
    FOV_CLAMP,
    T_MIN,
)
from song.render.camera import Camera
from song.render.gaussians import GaussianSet


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of wxyz quaternions (N, 4) (normalised first)."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def sh_colours(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(N, 3) colours (before +0.5) of SH coefficients (N, K, 3) along unit directions (N, 3)."""
    x, y, z = (dirs[:, k : k + 1] for k in range(3))
    out = C0 * sh[:, 0]
    k = sh.shape[1]
    if k > 1:
        out = out - C1 * y * sh[:, 1] + C1 * z * sh[:, 2] - C1 * x * sh[:, 3]
    if k > 4:
        xx, yy, zz = x * x, y * y, z * z
        out = out + C2[0] * x * y * sh[:, 4] + C2[1] * y * z * sh[:, 5] + C2[2] * (2 * zz - xx - yy) * sh[:, 6]
        out = out + C2[3] * x * z * sh[:, 7] + C2[4] * (xx - yy) * sh[:, 8]
    if k > 9:
        out = out + C3[0] * y * (3 * xx - yy) * sh[:, 9] + C3[1] * x * y * z * sh[:, 10]
        out = out + C3[2] * y * (4 * zz - xx - yy) * sh[:, 11] + C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
        out = out + C3[4] * x * (4 * zz - xx - yy) * sh[:, 13] + C3[5] * z * (xx - yy) * sh[:, 14]
        out = out + C3[6] * x * (xx - 3 * yy) * sh[:, 15]
    return out


def render_reference(
    gaussians: GaussianSet, camera: Camera, background: tuple[float, float, float] = (0.0, 0.0, 0.0), eps2d: float = 0.3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Float images ``(rgb (H, W, 3), depth (H, W), alpha (H, W))`` by per-pixel compositing."""
    g = gaussians
    means = g.means.astype(np.float64)
    cam = camera.to_camera(means)
    x, y, z = cam.T
    keep = (z >= camera.near) & (z <= camera.far) & (g.opacities >= ALPHA_MIN)
    rot = quat_matrix(g.quats.astype(np.float64))
    m = rot * g.scales.astype(np.float64)[:, None, :]
    cov_world = m @ np.transpose(m, (0, 2, 1))
    cov_cam = camera.rotation @ cov_world @ camera.rotation.T
    w, h = camera.width, camera.height
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    tan_x, tan_y = 0.5 * w / fx, 0.5 * h / fy
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = z * np.clip(x / z, -(cx / fx + FOV_CLAMP * tan_x), (w - cx) / fx + FOV_CLAMP * tan_x)
        ty = z * np.clip(y / z, -(cy / fy + FOV_CLAMP * tan_y), (h - cy) / fy + FOV_CLAMP * tan_y)
        jac = np.zeros((len(z), 2, 3))
        jac[:, 0, 0], jac[:, 0, 2] = fx / z, -fx * tx / z**2
        jac[:, 1, 1], jac[:, 1, 2] = fy / z, -fy * ty / z**2
        cov2d = jac @ cov_cam @ np.transpose(jac, (0, 2, 1)) + eps2d * np.eye(2)
        det = cov2d[:, 0, 0] * cov2d[:, 1, 1] - cov2d[:, 0, 1] ** 2
        keep &= det > 0
        mean2d = np.stack([fx * x / z + cx, fy * y / z + cy], axis=-1)
    dirs = means - camera.position
    dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-300)
    colours = np.maximum(sh_colours(g.sh.astype(np.float64), dirs) + 0.5, 0.0)
    order = [i for i in np.argsort(z, kind="stable") if keep[i]]
    rgb = np.zeros((h, w, 3))
    depth = np.zeros((h, w))
    alpha = np.zeros((h, w))
    for row in range(h):
        for col in range(w):
            p = np.array([col + 0.5, row + 0.5])
            trans, acc, acc_d = 1.0, np.zeros(3), 0.0
            for i in order:
                inv = np.linalg.inv(cov2d[i])
                d = mean2d[i] - p
                sigma = 0.5 * d @ inv @ d
                if sigma < 0:
                    continue
                a = min(ALPHA_MAX, float(g.opacities[i]) * np.exp(-sigma))
                if a < ALPHA_MIN:
                    continue
                if trans * (1 - a) <= T_MIN:
                    break
                acc += colours[i] * a * trans
                acc_d += z[i] * a * trans
                trans *= 1 - a
            rgb[row, col] = acc + trans * np.asarray(background)
            alpha[row, col] = 1 - trans
            depth[row, col] = acc_d / (1 - trans) if trans < 1 else 0.0
    return rgb, depth, alpha
