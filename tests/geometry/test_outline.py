"""The nearest point of an outline, against shapely."""

from __future__ import annotations

import numpy as np
from shapely.geometry import Point, Polygon

from song.geometry.outline import nearest_on_outline


def test_nearest_on_outline_matches_shapely() -> None:
    rng = np.random.default_rng(5)
    outline = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.5], [0.0, 1.0]])
    ring = Polygon(outline).exterior
    points = rng.uniform(-1.0, 3.0, (200, 2))
    nearest, dist = nearest_on_outline(outline, points)
    for p, q, d in zip(points, nearest, dist, strict=True):
        ref = ring.interpolate(ring.project(Point(p)))
        assert abs(d - ring.distance(Point(p))) < 1e-12
        np.testing.assert_allclose(q, [ref.x, ref.y], atol=1e-9)
