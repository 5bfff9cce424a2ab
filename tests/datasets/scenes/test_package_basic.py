from pathlib import Path

import numpy as np

from song.datasets.scenes import load_scene_package


def test_two_room_scene_loads_and_maps_pixels(make_scene) -> None:
    root: Path = make_scene()
    package = load_scene_package(root)
    grid = package.occupancy
    assert grid.shape == (80, 160)
    # DESIGN §4.1 mapping: cell (rows-1, 0) is the lower-left cell, centre at (res/2, res/2)
    np.testing.assert_allclose(grid.to_world(np.array([79, 0])), [0.025, 0.025])
    np.testing.assert_array_equal(grid.to_cell(np.array([0.025, 0.025])), [79, 0])
    np.testing.assert_array_equal(grid.to_cell(grid.to_world(np.array([[3, 7], [50, 120]]))), [[3, 7], [50, 120]])
    assert grid.is_free(np.array([[2.0, 2.0], [4.0, 2.0], [4.0, 0.5], [-1.0, 2.0]])).tolist() == [
        True,
        True,
        False,
        False,
    ]
