"""The robot camera: posed avatars appear where the crowd put them, at their depth; sensors are deterministic."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from song.datasets.bench.types import pedestrian_states
from song.render import robot_camera
from song.runtime.robot import Pose
from song.runtime.vision import SceneView
from tests.pipeline.binding.test_stage import _bound, pool  # noqa: F401  (module-scoped pool fixture)
from tests.runtime.helpers import bound_scene, episode, track

W, H = 160, 120


def _camera(ep, pose: Pose):
    cam = ep.params.camera
    return robot_camera(pose.x, pose.y, pose.yaw, cam.height_m, cam.hfov_deg, W, H, cam.near_m, cam.far_m)


def _check_person_at(view: SceneView, ep, pose: Pose, t: float, xy: np.ndarray) -> None:
    """The person standing at ``xy`` covers the pixel their body centre projects to, at its depth."""
    out = view.render(pose, t, W, H)
    camera = _camera(ep, pose)
    uv, z = camera.project(np.array([[xy[0], xy[1], ep.params.camera.height_m]]))
    j, i = int(uv[0, 0]), int(uv[0, 1])
    assert 0 <= j < W and 0 <= i < H
    assert out.alpha[i, j] > 0.9
    assert abs(float(out.depth[i, j]) - float(z[0])) < 0.2  # a torso is ~0.25 m deep: front surface
    # and nowhere else: columns well away from the body stay empty (no scene Gaussians here)
    half_width_px = camera.fx * 0.6 / z[0]
    far_cols = np.abs(np.arange(W) + 0.5 - uv[0, 0]) > half_width_px
    assert out.alpha[:, far_cols].max() < 0.05


def test_body_proxy_appears_at_its_projected_pixel() -> None:
    ped = track(7, (4.0, 3.5), (4.0, 3.49), speed=0.01)  # standing still at (4, 3.5)
    ep = episode(start=(1.0, 3.0), peds=[ped])
    view = SceneView(backend="numba")
    view.reset(ep)
    _check_person_at(view, ep, Pose(1.0, 3.0, 0.0), 0.0, np.array([4.0, 3.5]))
    behind = view.render(Pose(1.0, 3.0, np.pi), 0.0, W, H)  # facing away: nobody
    assert behind.alpha.max() < 0.05


def test_lbs_posed_avatar_appears_where_the_crowd_put_it(make_scene, tmp_path: Path, pool) -> None:  # noqa: F811
    ctx = _bound(make_scene, tmp_path, pool)
    tracks, avatars = bound_scene(ctx.scene_dir)
    ped = tracks[0]
    ep = replace(episode(peds=[ped]), avatars=[a for a in avatars if a.ped_id == ped.ped_id])
    view = SceneView(backend="numba")
    view.reset(ep)
    t = float(ped.t[len(ped.t) // 2])
    _, xy, _ = pedestrian_states([ped], t)
    # stand 3 m from the person, looking at them
    heading = 0.7
    pose = Pose(xy[0, 0] - 3.0 * np.cos(heading), xy[0, 1] - 3.0 * np.sin(heading), heading)
    _check_person_at(view, ep, pose, t, xy[0])
    again = SceneView(backend="numba")
    again.reset(ep)
    assert (again.render(pose, t, W, H).rgb == view.render(pose, t, W, H).rgb).all()


def test_avatars_take_the_scene_light_and_cast_a_contact_shadow(make_scene) -> None:
    """In a lit scene a person is shaded by the probes where they stand and darkens the floor below them."""
    from song.datasets.scenes.lights import LIGHTS_FILE, read_lights, write_lights
    from song.datasets.scenes.package import USD_PROXY
    from song.datasets.scenes.splat import dress_package

    root = make_scene()
    dress_package(root)
    ped = track(7, (2.5, 2.0), (2.5, 1.99), speed=0.01)  # standing still in room A
    pose = Pose(0.6, 2.0, 0.0)
    unlit = SceneView(backend="numba")
    unlit.reset(episode(start=(0.6, 2.0), peds=[ped]))
    lit = SceneView(backend="numba")
    lit.reset(replace(episode(start=(0.6, 2.0), peds=[ped]), usd_path=root / USD_PROXY))
    a, b = unlit.posed_avatars([0], 0.0), lit.posed_avatars([0], 0.0)
    assert len(a) == 1 and len(b) == 2  # the lit one brings its shadow
    shadow = b[0]
    assert np.allclose(shadow.means[0, :2], [2.5, 2.0], atol=0.02) and shadow.means[0, 2] < 0.01
    # the body's colours change with the light, its shape does not
    assert np.array_equal(a[0].means, b[1].means) and not np.array_equal(a[0].sh, b[1].sh)
    # twice the light: brighter (the exposure is fixed by the file, so the light alone changes)
    rig = read_lights(root / LIGHTS_FILE)
    brighter = [light.model_copy(update={"power_w": 2 * light.power_w}) for light in rig.lights]
    ev = lit._probes[root / USD_PROXY].exposure_ev
    write_lights(root / LIGHTS_FILE, rig.model_copy(update={"lights": brighter, "exposure_ev": ev}))
    dress_package(root)
    lit2 = SceneView(backend="numba")
    lit2.reset(replace(episode(start=(0.6, 2.0), peds=[ped]), usd_path=root / USD_PROXY))
    c = lit2.posed_avatars([0], 0.0)
    grey = lambda s: float(np.mean(0.5 + 0.282 * s.sh[:, 0, :]))  # noqa: E731
    assert grey(c[1]) > grey(b[1]) + 0.02
    out = lit.render(pose, 0.0, W, H)
    assert np.isfinite(out.depth).any()


def test_scene_views_sharing_a_cache_keep_the_scene_they_render(monkeypatch) -> None:
    """A cache shared by the envs of one process may drop a scene another env still renders: that env keeps
    its own reference, and views rendered together equal views rendered alone."""
    import song.runtime.vision as vision
    from song.render import GaussianSet

    def fake_scene(path):  # a wall of Gaussians 3 m ahead, its grey level from the path
        ys, zs = np.meshgrid(np.linspace(1.0, 6.0, 60), np.linspace(0.0, 2.0, 30))
        n = ys.size
        means = np.column_stack([np.full(n, 4.0), ys.ravel(), zs.ravel()])
        grey = 0.3 if str(path).endswith("a") else 0.8
        return GaussianSet.from_raw(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), np.log(0.05)),
                                    np.full(n, 4.0), np.full((n, 3), (grey - 0.5) / 0.28209479177387814))  # fmt: skip

    monkeypatch.setattr(vision, "scene_gaussians", fake_scene)
    monkeypatch.setattr(vision, "SCENE_CACHE", 1)
    base = episode(start=(1.0, 3.5), peds=[])
    a, b = (replace(base, gaussians_path=Path(name)) for name in ("scene_a", "scene_b"))
    first, second = SceneView(backend="numba"), SceneView(backend="numba")
    second.share_scenes(first)
    first.reset(a)
    second.reset(b)  # evicts scene_a from the shared cache while the first view is still on it
    pose = Pose(1.0, 3.5, 0.0)
    vision.render_together([(first, pose, 0.0, W, H, (0.0, 0.0)), (second, pose, 0.0, W, H, (0.0, 0.0))])
    together = first.render(pose, 0.0, W, H), second.render(pose, 0.0, W, H)
    alone = SceneView(backend="numba"), SceneView(backend="numba")
    alone[0].reset(a)
    alone[1].reset(b)
    for got, view in zip(together, alone, strict=True):
        assert got.rgb.tobytes() == view.render(pose, 0.0, W, H).rgb.tobytes()
    assert together[0].rgb[H // 2, W // 2, 0] < together[1].rgb[H // 2, W // 2, 0]  # each its own scene
