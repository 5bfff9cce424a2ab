"""The CUDA backend: gsplat's ``rasterization`` with the same inputs and outputs as the numba renderer.

``rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, near_plane,
far_plane, eps2d, sh_degree, backgrounds, render_mode="RGB+ED")`` returns (C, H, W, 4) colour + expected
depth and (C, H, W, 1) alpha for C cameras. gsplat compiles its CUDA code on first use (nvcc needed);
callers that chose ``auto`` fall back to numba on any failure (:func:`song.render.render.render`).

Each :class:`GaussianSet` is uploaded once and kept on the device for as long as the set lives (keyed by
the object, dropped when it is garbage-collected): the runtime renders one static scene set every step
and only the posed avatars are new, so a step uploads ~100 k Gaussians instead of the whole scene. A
set is treated as immutable once rendered, as the numba backend already does for its chunk bounds.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np

from song.render.camera import Camera
from song.render.gaussians import GaussianSet
from song.render.output import RenderOutput

DEVICE = "cuda"  # tests point it at "cpu" to run the same code against a stand-in rasterizer
_RESIDENT: dict[int, tuple[Any, ...]] = {}  # id(set) -> (means, quats, scales, opacities, sh) on DEVICE


def _tensors(g: GaussianSet) -> tuple[Any, ...]:
    """The set's arrays on the device (uploaded on first use, released with the set)."""
    key = id(g)
    if key not in _RESIDENT:
        import torch

        def t(a: np.ndarray) -> Any:
            return torch.tensor(a, dtype=torch.float32, device=DEVICE)

        _RESIDENT[key] = (t(g.means), t(g.quats), t(g.scales), t(g.opacities), t(g.sh))
        weakref.finalize(g, _RESIDENT.pop, key, None)
    return _RESIDENT[key]


def _gather(sets: Sequence[GaussianSet]) -> tuple[tuple[Any, ...], int]:
    """All sets as one group of device tensors (SH padded to the highest degree) and that degree."""
    import torch

    parts = [_tensors(g) for g in sets if len(g)]
    if not parts:
        parts = [_tensors(GaussianSet.empty())]
    k = max(p[4].shape[1] for p in parts)
    sh = [p[4] if p[4].shape[1] == k else torch.nn.functional.pad(p[4], (0, 0, 0, k - p[4].shape[1])) for p in parts]
    if len(parts) == 1:
        return (*parts[0][:4], sh[0]), int(round(k**0.5)) - 1
    cat = [torch.cat([p[i] for p in parts]) for i in range(4)]
    return (*cat, torch.cat(sh)), int(round(k**0.5)) - 1


def render_gsplat_batch(
    sets: Sequence[GaussianSet], cameras: Sequence[Camera], background: np.ndarray, eps2d: float
) -> list[RenderOutput]:
    """The same Gaussians seen by several cameras, in one gsplat call.

    The cameras must share their size and clip planes (:func:`song.render.render.render_batch` checks).
    """
    import torch
    from gsplat import rasterization

    first = cameras[0]
    (means, quats, scales, opacities, sh), degree = _gather(sets)

    def t(a: np.ndarray) -> Any:
        return torch.tensor(a, dtype=torch.float32, device=DEVICE)

    views = t(np.stack([c.viewmat for c in cameras]))
    ks = t(np.stack([c.intrinsics for c in cameras]))
    bgs = t(np.broadcast_to(np.asarray(background, np.float64).reshape(1, 3), (len(cameras), 3)))
    colors, alphas, _ = rasterization(
        means=means,
        quats=quats,
        scales=scales,
        opacities=opacities,
        colors=sh,
        viewmats=views,
        Ks=ks,
        width=int(first.width),
        height=int(first.height),
        near_plane=float(first.near),
        far_plane=float(first.far),
        eps2d=float(eps2d),
        sh_degree=degree,
        backgrounds=bgs,
        render_mode="RGB+ED",
        packed=False,
        rasterize_mode="classic",
    )
    # the per-pixel finishing runs on the device too: only the four images come back
    rgb = colors[..., :3].float()
    alpha = alphas[..., 0].float()
    depth = torch.where(alpha > 0, colors[..., 3].float(), torch.zeros_like(alpha))
    rgb8 = torch.round(rgb.clamp(0.0, 1.0) * 255.0).to(torch.uint8)  # half to even, as np.rint
    rgb8, rgb, depth, alpha = (x.cpu().numpy() for x in (rgb8, rgb, depth, alpha))
    results = [RenderOutput(rgb8[c], depth[c], alpha[c], rgb[c]) for c in range(len(cameras))]
    return results


def render_gsplat(sets: Sequence[GaussianSet], camera: Camera, background: np.ndarray, eps2d: float) -> RenderOutput:
    """One view through gsplat on the current CUDA device; returns a :class:`RenderOutput`."""
    return render_gsplat_batch(sets, [camera], background, eps2d)[0]
