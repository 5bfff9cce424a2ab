"""Shared drawing helpers: the map image, world→pixel mapping, colours, MP4 writing (OpenCV)."""

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


def write_mp4(path: str | Path, frames: list[np.ndarray], fps: float) -> Path:
    """Write RGB frames as an MP4 (mp4v); dimensions are made even for the codec."""
    import cv2

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    h, w = frames[0].shape[:2]
    h2, w2 = h - h % 2, w - w % 2
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w2, h2))
    if not writer.isOpened():
        raise OSError(f"{path}: OpenCV could not open an MP4 writer")
    for frame in frames:
        writer.write(cv2.cvtColor(np.ascontiguousarray(frame[:h2, :w2]), cv2.COLOR_RGB2BGR))
    writer.release()
    return path


def label(image: np.ndarray, text: str, at: tuple[int, int], rgb=(20, 20, 20), size: float = 0.4) -> None:
    """Text with a white halo so it stays readable over any background."""
    import cv2

    cv2.putText(image, text, at, cv2.FONT_HERSHEY_SIMPLEX, size, (255, 255, 255), 3, cv2.LINE_AA)
    cv2.putText(image, text, at, cv2.FONT_HERSHEY_SIMPLEX, size, rgb, 1, cv2.LINE_AA)
