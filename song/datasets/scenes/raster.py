"""Drawing world-space shapes into an occupancy image (OpenCV with sub-pixel precision)."""

from __future__ import annotations

import numpy as np

SHIFT = 4  # OpenCV fixed-point bits: coordinates are drawn with 1/16-pixel precision


class Rasterizer:
    """A north-up uint8 image covering [x_min, x_max] × [y_min, y_max] at ``resolution`` m per cell."""

    def __init__(self, lo: tuple[float, float], hi: tuple[float, float], resolution: float, fill: int = 255) -> None:
        self.lo = np.asarray(lo, dtype=np.float64)
        self.resolution = resolution
        self.cols = int(round((hi[0] - lo[0]) / resolution))
        self.rows = int(round((hi[1] - lo[1]) / resolution))
        self.cells = np.full((self.rows, self.cols), fill, dtype=np.uint8)

    def _px(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[..., 0] - self.lo[0]) / self.resolution - 0.5
        row = self.rows - (xy[..., 1] - self.lo[1]) / self.resolution - 0.5
        return np.round(np.stack([col, row], axis=-1) * (1 << SHIFT)).astype(np.int32)

    def polygon(self, points: np.ndarray, value: int) -> None:
        """Fill a polygon (K, 2) in world metres."""
        import cv2

        cv2.fillPoly(self.cells, [self._px(points)], int(value), lineType=cv2.LINE_8, shift=SHIFT)

    def segment(self, a: np.ndarray, b: np.ndarray, thickness: float, value: int, caps: bool = True) -> None:
        """A straight strip of ``thickness`` metres from ``a`` to ``b`` (extended by half the thickness with caps)."""
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        d = b - a
        length = np.linalg.norm(d)
        if length < 1e-9:
            return
        d /= length
        n = np.array([-d[1], d[0]]) * thickness / 2
        ext = d * thickness / 2 if caps else 0.0
        self.polygon(np.array([a - ext - n, b + ext - n, b + ext + n, a - ext + n]), value)
