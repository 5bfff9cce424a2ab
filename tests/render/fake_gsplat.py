"""A stand-in for ``gsplat.rasterization`` that keeps its calling contract and renders with our reference.

It refuses what gsplat refuses (tensors on different devices, non-float32 inputs, shapes that do not
match ``[N, 3]``/``[N, 4]``/``[N]``/``[N, K, 3]``, K ≠ (sh_degree + 1)², viewmats ``[C, 4, 4]`` with Ks
``[C, 3, 3]`` and backgrounds ``[C, 3]``), counts the Gaussians it was given, and returns what gsplat's
``RGB+ED`` mode returns: ``(C, H, W, 4)`` colour + expected depth composited over the background and
``(C, H, W, 1)`` alpha. The images come from :mod:`song.render._render_reference`, so only the plumbing
is under test here; the real parity with gsplat is measured on a GPU by ``benchmarks/gpu.py``.
"""

from __future__ import annotations

import numpy as np

CALLS: list[dict] = []


def rasterization(
    means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane=0.01, far_plane=1e10,
    eps2d=0.3, sh_degree=None, backgrounds=None, render_mode="RGB", packed=True, rasterize_mode="classic",
):  # fmt: skip
    import torch

    from song.render._render_reference import render_reference
    from song.render.camera import Camera
    from song.render.gaussians import GaussianSet

    tensors = {"means": means, "quats": quats, "scales": scales, "opacities": opacities, "colors": colors}
    if backgrounds is None:
        backgrounds = torch.zeros((viewmats.shape[0], 3), dtype=torch.float32, device=means.device)
    tensors |= {"viewmats": viewmats, "Ks": Ks, "backgrounds": backgrounds}
    devices = {t.device for t in tensors.values()}
    if len(devices) != 1:
        raise RuntimeError(f"Expected all tensors to be on the same device, but found {sorted(map(str, devices))}")
    for name, t in tensors.items():
        if t.dtype != torch.float32:
            raise TypeError(f"{name} must be float32, got {t.dtype}")
    n = means.shape[0]
    assert means.shape == (n, 3) and quats.shape == (n, 4) and scales.shape == (n, 3), "Invalid shape"
    assert opacities.shape == (n,), "Invalid shape"
    assert sh_degree is not None and colors.shape == (n, (sh_degree + 1) ** 2, 3), "Invalid SH shape"
    c = viewmats.shape[0]
    assert viewmats.shape == (c, 4, 4) and Ks.shape == (c, 3, 3) and backgrounds.shape == (c, 3), "Invalid shape"
    assert render_mode == "RGB+ED" and not packed and rasterize_mode == "classic"
    CALLS.append({"gaussians": n, "cameras": c})

    g = GaussianSet(*(t.cpu().numpy() for t in (means, quats, scales, opacities, colors)))
    rgb, alpha = np.zeros((c, height, width, 4), np.float32), np.zeros((c, height, width, 1), np.float32)
    for k in range(c):
        view, K = viewmats[k].double().cpu().numpy(), Ks[k].double().cpu().numpy()
        rotation = view[:3, :3]
        camera = Camera(
            rotation, -rotation.T @ view[:3, 3], K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height, near_plane,
            far_plane,
        )  # fmt: skip
        image, depth, a = render_reference(g, camera, tuple(backgrounds[k].double().cpu().numpy()), eps2d)
        rgb[k, ..., :3], rgb[k, ..., 3], alpha[k, ..., 0] = image, depth, a
    return torch.from_numpy(rgb).to(means.device), torch.from_numpy(alpha).to(means.device), {}
