"""Gaussian PLY: standard 3DGS and PlayCanvas/SuperSplat compressed (DESIGN §4.2).

CONTRACT (other modules rely on these names and signatures):
    GaussianCloud            dataclass below
    read_gaussian_ply(path) -> GaussianCloud       (detects standard vs compressed)
    write_standard_ply(path, cloud) -> None
    write_compressed_ply(path, cloud) -> None      (deterministic bytes for the same cloud)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


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


def read_gaussian_ply(path: str | Path) -> GaussianCloud:
    raise NotImplementedError


def write_standard_ply(path: str | Path, cloud: GaussianCloud) -> None:
    raise NotImplementedError


def write_compressed_ply(path: str | Path, cloud: GaussianCloud) -> None:
    raise NotImplementedError
