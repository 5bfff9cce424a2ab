"""The gsplat backend's plumbing against a stand-in rasterizer (the real one needs CUDA: benchmarks/gpu.py)."""

from __future__ import annotations

import gc
import sys

import numpy as np
import pytest

from song.render import gsplat_backend as backend
from song.render import render, render_batch, robot_camera
from tests.render import fake_gsplat
from tests.render.test_render import _random_scene

torch = pytest.importorskip("torch")


@pytest.fixture
def stand_in(monkeypatch):
    monkeypatch.setitem(sys.modules, "gsplat", fake_gsplat)
    monkeypatch.setattr(backend, "DEVICE", "cpu")
    fake_gsplat.CALLS.clear()
    yield fake_gsplat.CALLS
    backend._RESIDENT.clear()


def test_gsplat_path_renders_what_the_reference_renders(stand_in) -> None:
    scene, person = _random_scene(0, n=150, degree=1), _random_scene(1, n=40, degree=0)  # mixed SH degrees
    cam = robot_camera(0.0, 0.0, 0.0, 0.8, 70.0, 32, 24)
    ours, theirs = (
        render([scene, person], cam, "reference", (0.2, 0.3, 0.4)),
        render([scene, person], cam, "gsplat", (0.2, 0.3, 0.4)),
    )
    assert stand_in == [{"gaussians": 190, "cameras": 1}]
    np.testing.assert_allclose(theirs.rgb_float, ours.rgb_float, atol=1e-6)
    np.testing.assert_allclose(theirs.alpha, ours.alpha, atol=1e-6)
    assert (theirs.depth[theirs.alpha == 0] == 0).all()
    np.testing.assert_allclose(theirs.depth, ours.depth, atol=1e-6)


def test_a_scene_set_is_uploaded_once_and_released_with_the_set(stand_in) -> None:
    scene = _random_scene(2, n=100)
    cam = robot_camera(0.0, 0.0, 0.0, 0.8, 70.0, 16, 12)
    render([scene, _random_scene(3, n=20)], cam, "gsplat")
    first = backend._RESIDENT[id(scene)][0]
    render([scene, _random_scene(4, n=20)], cam, "gsplat")  # a new avatar set, the same scene
    assert backend._RESIDENT[id(scene)][0] is first  # not uploaded again
    gc.collect()
    assert set(backend._RESIDENT) == {id(scene)}  # the avatars' tensors went with their sets
    del scene, first
    gc.collect()
    assert not backend._RESIDENT


def test_a_batch_is_one_call_and_equals_single_views(stand_in) -> None:
    scene = _random_scene(5, n=120)
    cams = [robot_camera(0.0, 0.1 * k, 0.2 * k, 0.8, 70.0, 20, 15) for k in range(3)]
    batch = render_batch(scene, cams, "gsplat")
    assert stand_in[0] == {"gaussians": 120, "cameras": 3}
    for cam, out in zip(cams, batch, strict=True):
        single = render(scene, cam, "numba")
        np.testing.assert_allclose(out.rgb_float, single.rgb_float, atol=1e-4)
        np.testing.assert_allclose(out.depth, single.depth, atol=1e-4)


def test_a_batch_needs_cameras_of_one_size() -> None:
    cams = [robot_camera(0, 0, 0, 0.8, 70.0, 20, 15), robot_camera(0, 0, 0, 0.8, 70.0, 40, 30)]
    with pytest.raises(ValueError, match="same size"):
        render_batch(_random_scene(6), cams, "numba")
    assert render_batch(_random_scene(6), [], "numba") == []
