"""Runtime posing of bound Gaussian avatars from their compact caches (η_col on real avatar Gaussians)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from song.runtime.avatars import count_inside_volume, gaussian_poser, make_collider
from tests.pipeline.binding.test_stage import _bound, pool  # noqa: F401  (module-scoped pool fixture)
from tests.runtime.helpers import bound_scene, episode


def test_collider_poses_the_bound_avatars(make_scene, tmp_path: Path, pool) -> None:  # noqa: F811
    ctx = _bound(make_scene, tmp_path, pool)
    tracks, avatars = bound_scene(ctx.scene_dir)
    ep = replace(episode(peds=tracks), avatars=avatars)
    pose = gaussian_poser(ep)
    assert pose is not None
    assert make_collider(ep).pose is not None
    for index, track in enumerate(tracks):
        for f in (0, len(track.t) // 2, len(track.t) - 1):
            points = pose(index, float(track.t[f]))
            assert abs(float(np.ptp(points[:, 2])) - 1.7) < 0.3  # a standing person's height
            centre = points[:, :2].mean(axis=0)
            assert np.linalg.norm(centre - track.xy[f]) < 0.2  # the body is where the crowd planned it
            torso = count_inside_volume(points, track.xy[f], 0.2, 0.8)
            assert torso > 5  # robot inside the torso: collision by η_col
            away = track.xy[f] + 0.9 * np.array([np.cos(track.yaw[f] + np.pi / 2), np.sin(track.yaw[f] + np.pi / 2)])
            assert count_inside_volume(points, away, 0.2, 0.8) == 0
    no_caches = replace(ep, avatars=[])
    assert gaussian_poser(no_caches) is None
