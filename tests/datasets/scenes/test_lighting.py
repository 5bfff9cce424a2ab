"""The light baker: physical falloff, shadows, a reference twin, determinism, the package's lights file."""

from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from song.datasets.scenes.lighting import (
    ProbeGrid,
    _irradiance_one,
    bake,
    probe_irradiance,
)
from song.datasets.scenes.lights import LIGHTS_FILE, Light, LightRig, read_lights, write_lights
from song.datasets.scenes.package import GAUSSIANS, USD_PROXY, load_scene_package
from song.datasets.scenes.ply import read_gaussian_ply
from song.datasets.scenes.splat import dress_package
from song.errors import SceneError
from song.render import render, robot_camera
from song.runtime.vision import scene_gaussians

WHITE = (1.0, 1.0, 1.0)


def _plane(half: float, spacing: float, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Surfel positions and normals (up) on a square, and its two triangles."""
    g = np.arange(-half + spacing / 2, half, spacing)
    xx, yy = np.meshgrid(g, g)
    pos = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)])
    return pos, np.tile([0.0, 0.0, 1.0], (len(pos), 1))


def _quad(half: float, z: float = 0.0) -> np.ndarray:
    a, b, c, d = [(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)]
    return np.array([[a, b, c], [a, c, d]], dtype=np.float64)


def _box(lo, hi) -> np.ndarray:
    """12 triangles of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], dtype=np.float64)
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]  # fmt: skip
    return v[np.array(faces)]


def _point(power: float, position) -> Light:
    return Light(id="bulb", kind="point", role="lamp", position=position, power_w=power, colour=WHITE)


def test_point_light_over_a_plane_falls_off_as_cos_over_r_squared() -> None:
    pos, normals = _plane(3.0, 0.035)
    height, power = 2.0, 100.0
    rig = LightRig(lights=[_point(power, (0.0, 0.0, height))], exposure_ev=0.0)
    result = bake(pos, normals, np.full((len(pos), 3), 0.5), np.ones(len(pos)), _quad(3.2), rig)
    r = np.linalg.norm(pos - [0, 0, height], axis=1)
    expected = power / (4 * math.pi) * (height / r) / r**2
    away = np.abs(pos[:, :2]).max(axis=1) < 2.8  # the trilinear interpolation drops cells past the edge
    ratio = result.irradiance[away, 1] / expected[away]
    assert np.abs(ratio - 1).max() < 0.02, (ratio.min(), ratio.max())
    assert np.allclose(result.irradiance[:, 0], result.irradiance[:, 2])  # a white light stays white


def test_a_box_casts_a_shadow_and_occluded_surfels_get_no_direct_light() -> None:
    pos, normals = _plane(3.0, 0.035)
    light = (0.0, 0.0, 2.5)
    box_lo, box_hi = (-0.4, -0.4, 1.0), (0.4, 0.4, 1.2)
    rig = LightRig(lights=[_point(100.0, light)], exposure_ev=0.0)
    tris = np.concatenate([_quad(3.2), _box(box_lo, box_hi)])
    result = bake(pos, normals, np.zeros((len(pos), 3)), np.ones(len(pos)), tris, rig)  # black: no bounce
    # the shadow of a point light: the box's top face projected from the light onto the floor
    edge = 0.4 * light[2] / (light[2] - box_hi[2])
    reach = np.abs(pos[:, :2]).max(axis=1)
    # the shadowed share is blurred over ±2 texels and interpolated over one more: 0.3 m
    umbra = reach < edge - 0.32
    lit = reach > edge + 0.32
    assert umbra.sum() > 100 and np.all(result.irradiance[umbra] == 0.0)
    r = np.linalg.norm(pos - light, axis=1)
    expected = 100.0 / (4 * math.pi) * (light[2] / r) / r**2
    lit &= np.abs(pos[:, :2]).max(axis=1) < 2.8
    assert np.allclose(result.irradiance[lit, 0], expected[lit], rtol=0.02)


def test_rect_light_formula_matches_a_brute_force_integral() -> None:
    """Lambert's polygon formula (clipped to the horizon) against a dense sum over the emitter's area."""
    rng = np.random.default_rng(3)
    light = Light(id="panel", kind="rect", role="ceiling", position=(0.2, -0.1, 2.0), normal=(0, 0, -1),
                  u_axis=(1, 0, 0), size=(0.6, 0.4), power_w=40.0, colour=WHITE)  # fmt: skip
    u, v, n = light.frame()
    c = np.asarray(light.position)
    k = 400
    a, b = np.meshgrid((np.arange(k) + 0.5) / k - 0.5, (np.arange(k) + 0.5) / k - 0.5)
    samples = c + a.reshape(-1, 1) * light.size[0] * u + b.reshape(-1, 1) * light.size[1] * v
    d_area = light.area / len(samples)
    for _ in range(12):
        p = rng.uniform([-1, -1, 0], [1, 1, 1.9])
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        d = samples - p
        r = np.linalg.norm(d, axis=1)
        cos_r = np.maximum(d @ normal / r, 0)
        cos_e = np.maximum(-(d @ n) / r, 0)
        reference = light.radiance * np.sum(cos_e * cos_r / r**2) * d_area
        got = _irradiance_one(p, normal, 0, c, u, v, n, np.array(light.size) / 2, light.radiance, 0.0)
        assert got == pytest.approx(reference, rel=0.01, abs=1e-3), (p, normal)


def test_light_changes_colour_only_depth_is_unchanged(make_scene, tmp_path: Path) -> None:
    root = make_scene()
    dress_package(root, light=False)
    unlit = read_gaussian_ply(root / GAUSSIANS)
    dress_package(root)
    lit = read_gaussian_ply(root / GAUSSIANS)
    for field in ("means", "quats", "log_scales", "opacity_logits"):
        assert np.array_equal(getattr(lit, field), getattr(unlit, field)), field
    assert not np.array_equal(lit.sh_dc, unlit.sh_dc)
    camera = robot_camera(2.0, 1.0, 0.0, 0.8, 70.0, 160, 120)
    a = render(scene_gaussians(root / GAUSSIANS), camera)
    dress_package(root, light=False)
    b = render(scene_gaussians(root / GAUSSIANS), camera)
    assert np.array_equal(a.depth, b.depth)


def test_lights_are_written_read_back_edited_and_rebaked(make_scene) -> None:
    root = make_scene()
    dress_package(root)
    rig = read_lights(root / LIGHTS_FILE)
    assert rig.lights and {light.role for light in rig.lights} >= {"ceiling"}
    text = (root / USD_PROXY).read_text()
    assert text.count("def RectLight") + text.count("def SphereLight") == len(rig.lights)
    first = read_gaussian_ply(root / GAUSSIANS).sh_dc.copy()
    # an edit survives a re-bake (the file is never rewritten) and changes the colours
    dimmer = rig.model_copy(update={"exposure_ev": -1.0})
    write_lights(root / LIGHTS_FILE, dimmer)
    dress_package(root)
    assert read_lights(root / LIGHTS_FILE) == dimmer
    assert not np.array_equal(read_gaussian_ply(root / GAUSSIANS).sh_dc, first)
    load_scene_package(root)  # the package still validates


@pytest.mark.parametrize(
    ("patch", "field"),
    [
        ({"lights": [{"id": "a", "kind": "rect", "role": "ceiling", "position": [0, 0, 2], "power_w": 1}]}, "lights.0"),
        ({"exposure_ev": float("nan")}, "exposure_ev"),
        ({"version": 7}, "version"),
        ({"lights": [{"id": "a", "kind": "point", "role": "lamp", "position": [0, 0, 2], "power_w": -1}]}, "power_w"),
    ],
)
def test_bad_lights_file_names_the_file_and_field(make_scene, patch: dict, field: str) -> None:
    root = make_scene()
    data = {"format": "song.lights", "version": 1, "exposure_ev": None, "lights": []}
    data.update(patch)
    (root / LIGHTS_FILE).write_text(json.dumps(data).replace("NaN", "1e999"))
    with pytest.raises(SceneError) as info:
        load_scene_package(root)
    assert LIGHTS_FILE in str(info.value) and field in str(info.value)


def _ply_hash(root: Path) -> str:
    return hashlib.sha256((root / GAUSSIANS).read_bytes()).hexdigest()


def test_bake_is_identical_whatever_the_thread_count(make_scene) -> None:
    root = make_scene()
    dress_package(root)
    here = _ply_hash(root)
    (root / GAUSSIANS).unlink()
    code = f"from song.datasets.scenes.splat import dress_package; dress_package({str(root)!r})"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-c", code], check=True, env=env, timeout=300)
    assert _ply_hash(root) == here


def test_probe_grid_lights_avatars_where_the_scene_is_lit(make_scene) -> None:
    from song.datasets.scenes.usd import read_usd_lighting

    root = make_scene()
    dress_package(root)
    probes = ProbeGrid.from_json(read_usd_lighting(root / USD_PROXY))
    package = load_scene_package(root)
    free = package.occupancy.to_world(np.argwhere(package.occupancy.free)[::50])
    e = probe_irradiance(probes, free)
    assert np.all(np.isfinite(e)) and np.all(e > 0)
    # a light switched off leaves the probes dark (no light from nowhere)
    rig = read_lights(root / LIGHTS_FILE)
    write_lights(root / LIGHTS_FILE, rig.model_copy(update={"lights": [], "exposure_ev": 0.0}))
    dress_package(root)
    dark = ProbeGrid.from_json(read_usd_lighting(root / USD_PROXY))
    assert np.all(dark.values == 0)


def test_lit_generation_is_identical_whatever_the_worker_count(tmp_path: Path) -> None:
    from song.datasets.scenes.generate import generate_scenes

    trees = []
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        generate_scenes(2, seed=4, out_dir=out, spacing=0.1, workers=workers)
        trees.append({p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()})
    assert trees[0].keys() == trees[1].keys() and any(p.name == LIGHTS_FILE for p in trees[0])
    assert trees[0] == trees[1]


def test_compiled_buckets_and_cell_keys_match_their_numpy_twins() -> None:
    """The bake's compiled texel keys equal the plain numpy expressions, ties and exact axes included."""
    from song.datasets.scenes import lighting as lit

    rng = np.random.default_rng(0)
    normals = rng.normal(size=(50_000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[:600] = lit._AXES[rng.integers(0, 6, 600)]  # exactly on an axis
    normals[600:700] = [np.sqrt(0.5), -np.sqrt(0.5), 0.0]  # a tie: the first axis wins, as argmax
    bucket = lit.buckets(normals)
    np.testing.assert_array_equal(bucket, np.argmax(normals @ lit._AXES.T, axis=1))
    pos = rng.uniform(-3.0, 12.0, size=(50_000, 3))
    pos[:500] = np.round(pos[:500], 1)  # on cell boundaries
    lo, dims, h = np.array([-1.0137, -2.0137, -0.5137]), np.array([700, 800, 300]), 0.1
    step = np.full((len(pos), 3), h)
    step[np.arange(len(pos)), bucket // 2] = lit.DEPTH_M
    cell = np.clip(np.floor((pos - lo) / step).astype(np.int64), 0, dims - 1)
    np.testing.assert_array_equal(lit.cell_keys(pos, bucket, h, lo, dims), lit._encode(cell, bucket, dims))


def test_texel_hash_lookup_matches_a_binary_search() -> None:
    """The texels' key table finds exactly what a search of the sorted keys finds (absent and negative keys too)."""
    from song.datasets.scenes import lighting as lit

    rng = np.random.default_rng(1)
    keys = np.unique(rng.integers(0, 10**9, 40_000))
    slots = lit._key_table(keys)
    queries = np.concatenate([keys[rng.integers(0, len(keys), 20_000)], rng.integers(-(10**6), 10**9, 20_000)])
    k = np.minimum(np.searchsorted(keys, queries), len(keys) - 1)
    np.testing.assert_array_equal(lit._find_all(keys, slots, queries), np.where(keys[k] == queries, k, -1))
    assert len(slots) >= 2 * len(keys) and (np.sort(slots[slots >= 0]) == np.arange(len(keys))).all()


def test_ray_queries_split_over_threads_equal_one_query(monkeypatch: pytest.MonkeyPatch) -> None:
    """Embree queries cut into slices on several threads give every ray the answer one query gives."""
    import numba

    from song.datasets.scenes import lighting as lit

    rng = np.random.default_rng(2)
    tracer = lit.Tracer(rng.uniform(0, 4, (3000, 3, 3)))
    origins = rng.uniform(0, 4, (5000, 3))
    dirs = rng.normal(size=(5000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dists = rng.uniform(0.1, 3.0, 5000)
    whole = tracer.occluded(origins, dirs, dists), tracer.intersect(origins, dirs)
    monkeypatch.setattr(lit, "PARALLEL_RAYS", 1000)
    monkeypatch.setattr(numba, "get_num_threads", lambda: 3)  # three uneven slices
    split = tracer.occluded(origins, dirs, dists), tracer.intersect(origins, dirs)
    assert whole[0].any() and not whole[0].all()
    np.testing.assert_array_equal(whole[0], split[0])
    for a, b in zip(whole[1], split[1], strict=True):
        np.testing.assert_array_equal(a, b)


def test_compiled_grouping_sums_blur_and_emitters_match_their_numpy_twins() -> None:
    """The bake's compiled grouping, sums, surface blur, lit shares and emitter lookup equal plain numpy."""
    from song.datasets.scenes import lighting as lit

    rng = np.random.default_rng(5)
    keys = rng.integers(0, 5_000, 60_000) * 7 - 3  # repeats, negatives
    uniq, index = lit.group_keys(keys)
    ref_uniq, ref_index = np.unique(keys, return_inverse=True)
    np.testing.assert_array_equal(uniq, ref_uniq)
    np.testing.assert_array_equal(index, ref_index)
    values = rng.normal(size=(60_000, 4))
    expected = np.column_stack([np.bincount(index, weights=values[:, c], minlength=len(uniq)) for c in range(4)])
    assert np.array_equal(lit.sum_by(index, values, len(uniq)), expected)  # same additions, same order: bit for bit
    # a texel's weight and weighted position and normal sums, without the stacked temporaries: bit for bit
    pos, nrm, w = values[:, :3], rng.normal(size=(60_000, 3)), rng.uniform(0.5, 3.0, 60_000)
    count, sums = lit._weighted_sums(index, np.ascontiguousarray(pos), nrm, w, len(uniq))
    assert np.array_equal(count, lit.sum_by(index, w[:, None], len(uniq))[:, 0])
    assert np.array_equal(sums, lit.sum_by(index, np.hstack([pos, nrm]) * w[:, None], len(uniq)))

    # texels of points on a few axis planes: the blur against its numpy twin, bit for bit
    pts = rng.uniform(0.0, 3.0, (40_000, 3))
    normals = lit._AXES[rng.integers(0, 6, len(pts))]
    axis = np.argmax(np.abs(normals), axis=1)
    pts[np.arange(len(pts)), axis] = np.round(pts[np.arange(len(pts)), axis])  # on planes x, y or z = 0..3
    lo, dims = np.full(3, -0.6137), np.array([400, 400, 400])
    fine = lit.Texels.of(pts, normals, lit.buckets(normals), lit.TEXEL_M, lo, dims)
    field = rng.uniform(size=(len(fine.keys), 3))
    assert np.array_equal(fine.blur(field, 2), lit.blur_reference(fine, field, 2))

    k, lights = 500, 7
    e = rng.uniform(0, 2, (k, lights)) * (rng.uniform(size=(k, lights)) > 0.3)
    tex, light = rng.integers(0, k, 4000), rng.integers(0, lights, 4000)
    blocked, colour = rng.uniform(size=4000) > 0.5, rng.uniform(0.5, 1.0, (lights, 3))
    assert np.array_equal(
        lit._lit_share(tex, light, blocked, e, colour), lit._lit_share_reference(tex, light, blocked, e, colour)
    )


def test_emitter_lookup_finds_what_testing_every_light_finds() -> None:
    """Surfels drawn as a light's face: the grid-culled lookup equals testing every surfel against every light."""
    from song.datasets.scenes import lighting as lit

    rng = np.random.default_rng(6)
    n = 30_000
    pos = np.column_stack([rng.uniform(0, 9, n), rng.uniform(0, 7, n), rng.choice([0.0, 1.2, 2.79, 2.8], n)])
    normals = lit._AXES[rng.choice([4, 5, 1], n)]
    kind = np.array([0, 0, 1, 0, 0])
    centre = np.array([[2.0, 2.0, 2.8], [2.5, 2.2, 2.8], [4.0, 4.0, 2.0], [8.95, 3.0, 1.2], [7.0, 6.0, 2.8]])
    down, west = np.array([0.0, 0, -1]), np.array([-1.0, 0, 0])
    n_ = np.array([down, down, down, west, down])
    u = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0], [0.6, 0.8, 0]])
    v = np.cross(n_, u)
    half = np.array([[0.6, 0.3], [0.6, 0.3], [0.1, 0.1], [1.0, 0.7], [0.9, 0.2]])
    pos[:200] = centre[0] + rng.uniform(-0.7, 0.7, (200, 3)) * [1, 0.5, 0]  # around a light's edge
    normals[:200] = [0.0, 0.0, -1.0]
    pos[200:400] = centre[3] + rng.uniform(-1.1, 1.1, (200, 3)) * [0.02, 1, 1]  # on a wall light's face
    normals[200:400] = [-1.0, 0.0, 0.0]
    got = lit._emitters(pos, normals, kind, centre, u, v, n_, half)
    want = lit._emitters_reference(pos, normals, kind, centre, u, v, n_, half)
    np.testing.assert_array_equal(got, want)
    assert all((got == j).any() for j in (0, 1, 3)) and (got >= 0).sum() > 250
