"""The CUDA backend: gsplat's ``rasterization`` with the same inputs and outputs as the numba renderer.

``rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane,
far_plane, eps2d, sh_degree, backgrounds, render_mode="RGB+ED")`` returns (1, H, W, 4) colour + expected
depth and (1, H, W, 1) alpha. gsplat compiles its CUDA code on first use (nvcc needed); callers that
chose ``auto`` fall back to numba on any failure (:func:`song.render.render.render`).
"""

from __future__ import annotations

import numpy as np

from song.render.camera import Camera
from song.render.gaussians import GaussianSet
from song.render.output import RenderOutput, to_uint8


def render_gsplat(gaussians: GaussianSet, camera: Camera, background: np.ndarray, eps2d: float):
    """One view through gsplat on the current CUDA device; returns a :class:`RenderOutput`."""
    import torch
    from gsplat import rasterization

    device = torch.device("cuda")

    def t(a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)

    degree = gaussians.sh_degree
    colors, alphas, _ = rasterization(
        means=t(gaussians.means),
        quats=t(gaussians.quats),
        scales=t(gaussians.scales),
        opacities=t(gaussians.opacities),
        colors=t(gaussians.sh),
        viewmats=t(camera.viewmat)[None],
        Ks=t(camera.intrinsics)[None],
        width=int(camera.width),
        height=int(camera.height),
        near_plane=float(camera.near),
        far_plane=float(camera.far),
        eps2d=float(eps2d),
        sh_degree=degree,
        backgrounds=t(background)[None],
        render_mode="RGB+ED",
        packed=False,
        rasterize_mode="classic",
    )
    out = colors[0].float().cpu().numpy()
    alpha = alphas[0, ..., 0].float().cpu().numpy()
    depth = np.where(alpha > 0, out[..., 3], 0.0).astype(np.float32)
    return RenderOutput(to_uint8(out[..., :3]), depth, alpha.astype(np.float32), out[..., :3].astype(np.float32))
