"""Closed 2-D outlines (object footprints): the nearest point of an outline to given points."""

from __future__ import annotations

import numpy as np


def nearest_on_outline(outline: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point of a closed outline nearest each point, and its distance.

    Args:
        outline: ``(K, 2)`` vertices of a closed polygon (the last joins the first), m.
        points: ``(T, 2)`` m.

    Returns:
        ``(nearest (T, 2), distance (T,))``, m.
    """
    a = np.asarray(outline, dtype=np.float64)
    ab = np.roll(a, -1, axis=0) - a
    rel = np.asarray(points, dtype=np.float64)[:, None] - a[None]
    s = np.clip((rel * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    off = rel - s[..., None] * ab  # (T, K, 2) from each edge's nearest point to the point
    dist = np.hypot(off[..., 0], off[..., 1])
    k = dist.argmin(axis=1)
    rows = np.arange(len(dist))
    return points - off[rows, k], dist[rows, k]
