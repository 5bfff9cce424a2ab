"""Activated 3D Gaussians, ready to render.

A Gaussian set holds what the rasterizer consumes: means, unit wxyz rotations, *linear* scales,
opacities in [0, 1] and colours as spherical-harmonic coefficients (degree 0 to 3). A scene is
activated once when it is loaded (exp of log-scales, sigmoid of opacity logits); avatars are posed per
step and appended. Every 256 consecutive Gaussians form a chunk with a bounding box (the SuperSplat PLY
stores its splats spatially sorted in such chunks), so whole chunks outside the view are culled
before projection.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SH_C0 = 0.28209479177387814  # Y_0^0: colour = 0.5 + SH_C0 · f_dc
CHUNK = 256
BOUND_SIGMAS = 3.5  # a chunk's box is its means grown by this many of its largest scale (gsplat cuts at 3.33σ)


def sh_degree_of(n_coeffs: int) -> int:
    """The SH degree of (degree + 1)² coefficients."""
    degree = int(round(np.sqrt(n_coeffs))) - 1
    if (degree + 1) ** 2 != n_coeffs or not 0 <= degree <= 3:
        raise ValueError(f"{n_coeffs} SH coefficients per channel: expected 1, 4, 9 or 16")
    return degree


@dataclass
class GaussianSet:
    """Activated Gaussians.

    Attributes:
        means: (N, 3) float32, m.
        quats: (N, 4) float32 unit rotations, wxyz.
        scales: (N, 3) float32 standard deviations along the rotated axes, m.
        opacities: (N,) float32 in [0, 1].
        sh: (N, K, 3) float32 SH coefficients, K = (degree + 1)² (K = 1: colour = 0.5 + SH_C0·sh).
    """

    means: np.ndarray
    quats: np.ndarray
    scales: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    _bounds: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    _log_alpha: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        n = len(self.means)
        self.means = np.ascontiguousarray(self.means, dtype=np.float32).reshape(n, 3)
        self.quats = np.ascontiguousarray(self.quats, dtype=np.float32).reshape(n, 4)
        self.scales = np.ascontiguousarray(self.scales, dtype=np.float32).reshape(n, 3)
        self.opacities = np.ascontiguousarray(self.opacities, dtype=np.float32).reshape(n)
        sh = np.asarray(self.sh, dtype=np.float32)
        self.sh = np.ascontiguousarray(sh.reshape(n, -1, 3) if n else sh.reshape(0, max(1, sh.size // 3 or 1), 3))
        sh_degree_of(self.sh.shape[1])

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        """Degree of the colour's spherical harmonics (0–3)."""
        return sh_degree_of(self.sh.shape[1])

    @classmethod
    def from_raw(
        cls,
        means: np.ndarray,
        quats: np.ndarray,
        log_scales: np.ndarray,
        opacity_logits: np.ndarray,
        sh_dc: np.ndarray,
        sh_rest: np.ndarray | None = None,
    ) -> GaussianSet:
        """Activate stored parameters: exp of log-scales, sigmoid of logits, normalised quaternions.

        Args:
            means: (N, 3) m.
            quats: (N, 4) wxyz, any norm.
            log_scales: (N, 3) natural log of σ (m).
            opacity_logits: (N,).
            sh_dc: (N, 3) degree-0 coefficients.
            sh_rest: (N, K − 1, 3) higher-degree coefficients, or None.
        """
        q = np.asarray(quats, dtype=np.float64)
        q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
        dc = np.asarray(sh_dc, dtype=np.float32)[:, None, :]
        sh = (
            dc
            if sh_rest is None or np.asarray(sh_rest).size == 0
            else np.concatenate([dc, np.asarray(sh_rest, np.float32)], axis=1)
        )
        return cls(
            means=means,
            quats=q,
            scales=np.exp(np.asarray(log_scales, dtype=np.float64)),
            opacities=1.0 / (1.0 + np.exp(-np.asarray(opacity_logits, dtype=np.float64))),
            sh=sh,
        )

    @classmethod
    def empty(cls, sh_coeffs: int = 1) -> GaussianSet:
        """A set with no Gaussians."""
        return cls(np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, sh_coeffs, 3)))

    def chunk_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per chunk of 256 consecutive Gaussians: (C, 3) lower and upper corners of its box, m (cached)."""
        if self._bounds is None:
            n = len(self)
            if n == 0:
                self._bounds = (np.zeros((0, 3)), np.zeros((0, 3)))
            else:
                starts = np.arange(0, n, CHUNK)
                grow = (BOUND_SIGMAS * self.scales.max(axis=1))[:, None]
                lo = np.minimum.reduceat(self.means - grow, starts, axis=0)
                hi = np.maximum.reduceat(self.means + grow, starts, axis=0)
                self._bounds = (lo.astype(np.float64), hi.astype(np.float64))
        return self._bounds

    def log_alpha_range(self) -> np.ndarray:
        """(N,) float64 ln(255·opacity): the Mahalanobis σ beyond which a Gaussian's α < 1/255 (cached)."""
        if self._log_alpha is None:
            with np.errstate(divide="ignore"):
                self._log_alpha = np.log(np.asarray(self.opacities, dtype=np.float64) * 255.0)
        return self._log_alpha

    def subset(self, index: np.ndarray) -> GaussianSet:
        """The Gaussians at ``index`` (a new set)."""
        return GaussianSet(
            self.means[index], self.quats[index], self.scales[index], self.opacities[index], self.sh[index]
        )


def concat(sets: list[GaussianSet]) -> GaussianSet:
    """One set holding all Gaussians of ``sets`` (SH padded with zeros to the highest degree)."""
    sets = [s for s in sets if len(s)]
    if not sets:
        return GaussianSet.empty()
    k = max(s.sh.shape[1] for s in sets)
    sh = [s.sh if s.sh.shape[1] == k else np.pad(s.sh, ((0, 0), (0, k - s.sh.shape[1]), (0, 0))) for s in sets]
    return GaussianSet(
        np.concatenate([s.means for s in sets]),
        np.concatenate([s.quats for s in sets]),
        np.concatenate([s.scales for s in sets]),
        np.concatenate([s.opacities for s in sets]),
        np.concatenate(sh),
    )
