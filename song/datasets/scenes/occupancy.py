"""Occupancy grid of a scene package: 8-bit PNG, 255 free, 0 occupied, 127 unknown."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song.datasets.limits import check_png_size
from song.errors import SceneError
from song.geometry.grid import cell_to_world, sample_mask, world_to_cell

FREE = 255
OCCUPIED = 0
UNKNOWN = 127


@dataclass(frozen=True)
class OccupancyGrid:
    """A north-up occupancy image placed in the world.

    Attributes:
        cells: (rows, cols) uint8; 255 free, 0 occupied, 127 unknown.
        resolution: metres per cell.
        origin: (x_min, y_min) of the lower-left image corner, metres.
    """

    cells: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the grid."""
        return self.cells.shape  # type: ignore[return-value]

    @property
    def free(self) -> np.ndarray:
        """(rows, cols) bool: cells a body may stand on (unknown counts as not free)."""
        return self.cells == FREE

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max), metres."""
        rows, cols = self.shape
        x0, y0 = self.origin
        return (x0, y0, x0 + cols * self.resolution, y0 + rows * self.resolution)

    def to_world(self, rc: np.ndarray) -> np.ndarray:
        """Cell centres (x, y) of (row, col) indices; see :func:`song.geometry.grid.cell_to_world`."""
        return cell_to_world(rc, self.shape[0], self.resolution, self.origin)

    def to_cell(self, xy: np.ndarray) -> np.ndarray:
        """(row, col) of the cells containing points (x, y)."""
        return world_to_cell(xy, self.shape[0], self.resolution, self.origin)

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """Bool per point: inside the grid and on a free cell."""
        return sample_mask(self.free, self.to_cell(xy), outside=False)


def read_occupancy_png(path: str | Path, resolution: float, origin: tuple[float, float]) -> OccupancyGrid:
    """Read an 8-bit single-channel occupancy PNG; raises :class:`SceneError` naming the file."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "", "file is missing")
    raw = path.read_bytes()
    check_png_size(raw, path, SceneError)  # before decoding: a small file may declare a huge image
    data = np.frombuffer(raw, dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise SceneError(path, "", "not a readable PNG image")
    if image.ndim != 2 or image.dtype != np.uint8:
        raise SceneError(path, "", f"expected an 8-bit single-channel image, got shape {image.shape} {image.dtype}")
    return OccupancyGrid(cells=np.ascontiguousarray(image), resolution=float(resolution), origin=tuple(origin))


def encode_occupancy_png(cells: np.ndarray) -> bytes:
    """PNG bytes of a (rows, cols) uint8 grid (deterministic: fixed compression level)."""
    import cv2

    if cells.ndim != 2 or cells.dtype != np.uint8:
        raise ValueError("occupancy must be a (rows, cols) uint8 array")
    ok, buffer = cv2.imencode(".png", cells, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise RuntimeError("OpenCV failed to encode the occupancy PNG")
    return buffer.tobytes()
