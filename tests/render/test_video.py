"""H.264 videos: the same frames give the same bytes, and they decode back to the frames."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from song.render import robot_camera
from song.render.render import render
from song.render.video import write_mp4
from tests.render.test_render import _random_scene

av = pytest.importorskip("av")


def _walk_frames(count: int = 40) -> np.ndarray:
    """A camera walking and turning through a random scene: moving content, as a robot records it."""
    scene = _random_scene(3, n=600, degree=1)
    return np.stack(
        [
            render(scene, robot_camera(0.02 * k, 0.01 * k, 0.015 * k, 0.8, 70.0, 64, 48), "numba").rgb
            for k in range(count)
        ]
    )


def test_the_same_frames_give_the_same_bytes_every_time(tmp_path: Path) -> None:
    """x264's macroblock-tree rate control varied between encodes of the same frames in one process."""
    frames = _walk_frames()
    digests = set()
    for k in range(6):
        stir = [np.full(int(n), 255, np.uint8) for n in np.random.default_rng(k).integers(1000, 100000, 50)]
        del stir  # earlier allocations leave the heap in a different state for each encode
        path = write_mp4(tmp_path / f"v{k}.mp4", frames, 10.0)
        digests.add(hashlib.sha256(path.read_bytes()).hexdigest())
    assert len(digests) == 1
    with av.open(str(tmp_path / "v0.mp4")) as container:
        decoded = np.stack([f.to_ndarray(format="rgb24") for f in container.decode(video=0)])
    assert decoded.shape == frames.shape
    assert np.abs(decoded.astype(int) - frames).mean() < 4  # lossy, but the same pictures
