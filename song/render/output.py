"""What every render backend returns (numba, reference and gsplat alike)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RenderOutput:
    """One rendered view.

    Attributes:
        rgb: (H, W, 3) uint8.
        depth: (H, W) float32 expected planar depth, m (0 where alpha is 0).
        alpha: (H, W) float32 coverage in [0, 1].
        rgb_float: (H, W, 3) float32 colour before clipping and quantisation.
    """

    rgb: np.ndarray
    depth: np.ndarray
    alpha: np.ndarray
    rgb_float: np.ndarray


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Float colour (any shape) → uint8: clipped to [0, 1], scaled by 255 and rounded."""
    return np.rint(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
