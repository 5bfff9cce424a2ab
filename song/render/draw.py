"""Shared drawing helpers: the map image, world→pixel mapping, colours, PNG (OpenCV) and H.264 MP4 (PyAV)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

PALETTE = np.array(
    [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ],
    dtype=np.uint8,
)
DIFFICULTY_COLOURS = {"easy": "#2ca02c", "medium": "#ff7f0e", "hard": "#d62728"}


def colour(index: int) -> tuple[int, int, int]:
    """An RGB colour per index (tab10)."""
    r, g, b = PALETTE[index % len(PALETTE)]
    return int(r), int(g), int(b)


@dataclass(frozen=True)
class Canvas:
    """A map picture and the mapping from world metres to its pixels (``scale`` pixels per metre)."""

    image: np.ndarray  # (H, W, 3) uint8 RGB
    origin: tuple[float, float]
    rows_m: float
    scale: float

    def px(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) world points → (..., 2) int pixel (col, row)."""
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[..., 0] - self.origin[0]) * self.scale
        row = (self.rows_m - (xy[..., 1] - self.origin[1])) * self.scale
        return np.stack([col, row], axis=-1).round().astype(np.int32)


def map_canvas(cells: np.ndarray, resolution: float, origin: tuple[float, float], max_pixels: int = 1400) -> Canvas:
    """Occupancy drawn as light floor / dark walls / grey unknown, scaled so the long side ≤ ``max_pixels``."""
    import cv2

    rows, cols = cells.shape
    scale_cells = max(1, int(max_pixels // max(rows, cols)))
    rgb = np.empty((rows, cols, 3), dtype=np.uint8)
    rgb[cells == 255] = (245, 243, 238)
    rgb[cells == 0] = (60, 60, 66)
    rgb[(cells != 255) & (cells != 0)] = (170, 170, 170)
    image = cv2.resize(rgb, (cols * scale_cells, rows * scale_cells), interpolation=cv2.INTER_NEAREST)
    return Canvas(image=image, origin=origin, rows_m=rows * resolution, scale=scale_cells / resolution)


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an RGB image as PNG."""
    import cv2

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise OSError(f"{path}: OpenCV could not write the PNG")
    return path


def label(image: np.ndarray, text: str, at: tuple[int, int], rgb=(20, 20, 20), size: float = 0.4) -> None:
    """Text on a light, slightly transparent box so it stays readable over any background.

    (An earlier white halo of offset copies of the text read as ghost letters over dark areas.)
    """
    import cv2

    font = cv2.FONT_HERSHEY_SIMPLEX
    (w, h), base = cv2.getTextSize(text, font, size, 1)
    x, y = at
    y0, y1 = max(0, y - h - 3), min(image.shape[0], y + base + 2)
    x0, x1 = max(0, x - 3), min(image.shape[1], x + w + 3)
    if y1 > y0 and x1 > x0:
        box = image[y0:y1, x0:x1].astype(np.float32)
        image[y0:y1, x0:x1] = (0.2 * box + 0.8 * 255).astype(image.dtype)
    cv2.putText(image, text, at, font, size, rgb, 1, cv2.LINE_AA)
