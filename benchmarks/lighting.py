"""The baked light against Blender Cycles: the same proxy geometry, albedos, lights, exposure and camera.

    .venv/bin/python benchmarks/lighting.py [--out runs/bench-lighting] [--samples 256] [--size 240x180]

Sets up its own environment for the reference (``bpy`` from PyPI in ``build/bench-envs/cycles``,
never a dependency of ``song``), then, for 4 scenes (2 procedural venues, 2 ProcTHOR houses from
``datasets/sample_scenes``) and 5 views each (:func:`song.viz.view.pick_view` with seeds 0–4, camera
0.8 m up, 70° wide):

- **SONG**: the scene's Gaussians baked with every surface in its material's base colour (textures
  off, so that both renderers see the same albedos), rendered by SONG's rasterizer;
- **Cycles**: the scene's proxy meshes (:func:`song.datasets.scenes.proxy.dressing_meshes`) with
  Lambertian materials of the same linear albedos, the same lights and exposure, path traced with
  ``--samples`` samples per pixel, 12 diffuse bounces, OpenImageDenoise, "Standard" view.

Per view: the Pearson correlation of log-luminance and the median absolute error of relative
luminance (|Y_song − Y_cycles| / Y_cycles, linear Rec. 709 luminance from the sRGB pixels); targets
≥ 0.85 and ≤ 15 %. Light units are calibrated first (a wall lit by one point light and by one
rectangle, each rendered by Cycles and compared with the closed form). Also reported: the median
share of the light that arrives after the third bounce (why the baker iterates to convergence), the
bake's seconds per million Gaussians, and side-by-side pictures (``<out>/compare_<scene>.png``: SONG top, Cycles below).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._common import ROOT, bench_env, emit  # noqa: E402

SCENES = ("office_0000", "clinic_0001", "procthor_house_6", "procthor_house_1")
ENV = ROOT / "build" / "bench-envs" / "cycles"
BPY_VERSION = "5.0.1"
HFOV, CAMERA_HEIGHT = 70.0, 0.8


def ensure_cycles() -> Path:
    """The Python of the benchmark's own ``bpy`` environment (created on first use)."""
    return bench_env(ENV, "import bpy", [f"bpy=={BPY_VERSION}"])


def luminance(png_rgb: np.ndarray) -> np.ndarray:
    """Linear Rec. 709 luminance of sRGB pixels in [0, 1]."""
    from song.datasets.scenes.materials import srgb_to_linear

    return srgb_to_linear(png_rgb) @ np.array([0.2126, 0.7152, 0.0722])


def _read_view(path: Path) -> np.ndarray:
    """Linear RGB radiance of a Cycles view (the ``.npy`` the render script saves beside its EXR)."""
    return np.load(path).astype(np.float64)


def _run_cycles(python: Path, job_dir: Path, job: dict, meshes: dict) -> list[np.ndarray]:
    """Cycles' images of a job (reused when the same job was rendered into ``job_dir`` before)."""
    job_dir.mkdir(parents=True, exist_ok=True)
    (job_dir / "job_input.json").write_text(json.dumps(job))
    import hashlib

    digest = hashlib.sha256(b"".join(np.ascontiguousarray(meshes[k]).tobytes() for k in sorted(meshes))).hexdigest()
    text = json.dumps({**job, "meshes_sha256": digest}, sort_keys=True)
    views = [job_dir / f"view_{i}.npy" for i in range(len(job["views"]))]
    done = job_dir / "job.json"
    if done.is_file() and done.read_text() == text and all(v.is_file() for v in views):
        return [_read_view(v) for v in views]
    done.unlink(missing_ok=True)
    np.savez(job_dir / "meshes.npz", **meshes)
    env = {**os.environ, "OMP_NUM_THREADS": "2"}
    out = subprocess.run(
        [str(python), str(ROOT / "benchmarks" / "_cycles_render.py"), str(job_dir)],
        capture_output=True, text=True, env=env, timeout=3600,
    )  # fmt: skip
    if out.returncode:
        raise RuntimeError(f"Cycles failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
    done.write_text(text)
    return [_read_view(v) for v in views]


def calibrate(python: Path, out: Path, samples: int) -> dict:
    """Blender watts per SONG watt for point and rect lights: a grey wall 2 m in front of each light."""
    from song.datasets.scenes.lighting import LightTable, _irradiance_one
    from song.datasets.scenes.lights import Light, LightRig

    wall = {
        "v0": np.array([[3, -3, -1], [3, 3, -1], [3, 3, 4], [3, -3, 4]], float),
        "f0": np.array([[0, 2, 1], [0, 3, 2]]),
    }
    albedo = 0.5
    lights = {
        "point": Light(id="p", kind="point", role="lamp", position=(1.0, 0.0, 1.5), power_w=100.0, colour=(1, 1, 1)),
        "area": Light(
            id="a",
            kind="rect",
            role="ceiling",
            position=(1.0, 0.0, 1.5),
            normal=(1, 0, 0),
            u_axis=(0, 1, 0),
            size=(0.5, 0.5),
            power_w=100.0,
            colour=(1, 1, 1),
        ),  # fmt: skip
    }
    units = {}
    for name, light in lights.items():
        job = {
            "materials": ["wall"], "albedos": [[albedo] * 3], "lights": [light.model_dump(mode="json")],
            "units": {"point": 1.0, "area": 1.0}, "samples": samples, "denoise": True,
            "views": [{"position": [0.0, 0.0, 1.5], "yaw": 0.0, "hfov_deg": 20.0, "size": [32, 32]}],
        }  # fmt: skip
        img = _run_cycles(python, out / f"calibrate_{name}", job, wall)[0]
        got = float(np.median(img[12:20, 12:20] @ np.array([0.2126, 0.7152, 0.0722])))
        t = LightTable.of(LightRig(lights=[light]))
        e = _irradiance_one(np.array([3.0, 0, 1.5]), np.array([-1.0, 0, 0]), t.kind[0], t.centre[0], t.u[0], t.v[0],
                            t.n[0], t.half[0], t.scale[0], t.radius[0])  # fmt: skip
        units[name] = round((albedo * e / math.pi) / got, 4)
    return units


def _views(root: Path, count: int) -> list[tuple[float, float, float]]:
    from song.viz.view import pick_view

    views = []
    # distinct poses first; a small house has few, so then nearer ones (poses of larger scenes unchanged)
    for seeds, far, turn in ((range(count * 3), 1.0, 0.5), (range(count * 3, count * 12), 0.3, 0.3)):
        for seed in seeds:
            if len(views) == count:
                return views
            pose = pick_view(root, HFOV, seed=seed)
            if all(math.dist(pose[:2], v[:2]) > far or abs(pose[2] - v[2]) > turn for v in views):
                views.append(pose)
    return views


def scene_job(root: Path, views, size, samples: int, units: dict):
    """(job, meshes, SONG images, synthesis seconds, Gaussians, beyond-third-bounce share, exposure) of one scene."""
    from song.datasets.scenes import lighting as baker
    from song.datasets.scenes import load_scene_package
    from song.datasets.scenes.dressing import DressingHints, build_dressing
    from song.datasets.scenes.lights import read_lights
    from song.datasets.scenes.materials import material_of, srgb_to_linear
    from song.datasets.scenes.proxy import dressing_meshes
    from song.datasets.scenes.splat import proxy_triangles, synthesize_gaussians
    from song.datasets.scenes.usd import read_usd_dressing
    from song.render import render, robot_camera
    from song.render.gaussians import GaussianSet

    package = load_scene_package(root)
    hints = DressingHints.from_json(read_usd_dressing(root / "scene_flat.usda"))
    dressing = build_dressing(package.semantic_map, package.occupancy, hints)
    solids, surfaces = dressing_meshes(dressing, {o.id: o.category for o in package.semantic_map.objects})
    rig = read_lights(root / "lights.json")
    tris = proxy_triangles(solids, surfaces)
    start = time.perf_counter()
    cloud, baked = synthesize_gaussians(dressing, lighting=(rig, tris), flat_materials=True)
    seconds = time.perf_counter() - start
    saved = baker.BOUNCES
    baker.BOUNCES = 3
    _, three = synthesize_gaussians(dressing, lighting=(rig.model_copy(update={"exposure_ev": baked.exposure_ev}), tris),
                                    flat_materials=True)  # fmt: skip
    baker.BOUNCES = saved
    total = np.maximum(baked.irradiance.sum(1), 1e-9)
    fourth = float(np.median((baked.irradiance - three.irradiance).sum(1) / total))
    gaussians = GaussianSet.from_raw(cloud.means, cloud.quats, cloud.log_scales, cloud.opacity_logits, cloud.sh_dc)
    images = []
    for x, y, yaw in views:
        camera = robot_camera(x, y, yaw, CAMERA_HEIGHT, HFOV, *size)
        images.append(render(gaussians, camera, background=(0, 0, 0)).rgb.astype(np.float64) / 255.0)
    groups: dict[str, list] = {}
    for m in [*solids, *surfaces]:
        groups.setdefault(m.material or "plaster_white", []).append(m)
    meshes, names, albedos = {}, [], []
    for k, (name, items) in enumerate(sorted(groups.items())):
        offsets = np.cumsum([0] + [len(m.vertices) for m in items])
        meshes[f"v{k}"] = np.concatenate([np.asarray(m.vertices, float) for m in items])
        meshes[f"f{k}"] = np.concatenate([np.asarray(m.faces) + o for m, o in zip(items, offsets, strict=False)])
        names.append(name)
        albedos.append(srgb_to_linear(np.asarray(material_of(name).base)).tolist())
    job = {
        "materials": names, "albedos": albedos, "lights": [light.model_dump(mode="json") for light in rig.lights],
        "units": units, "samples": samples, "denoise": True,
        "views": [{"position": [x, y, CAMERA_HEIGHT], "yaw": yaw, "hfov_deg": HFOV, "size": list(size)}
                  for x, y, yaw in views],
    }  # fmt: skip
    return job, meshes, images, seconds, len(cloud), fourth, baked.exposure_ev


def avatar_light_cost(root: Path, frames: int = 20) -> dict:
    """Milliseconds to shade five 40 k-Gaussian avatars from the probes (plus their contact shadows) per step,
    against one 320×240 frame of the lit scene with those avatars, interleaved."""
    from song.datasets.scenes.lighting import ProbeGrid, probe_irradiance
    from song.datasets.scenes.usd import read_usd_lighting
    from song.render import render, robot_camera
    from song.runtime.vision import _Avatar, contact_shadows, scene_gaussians
    from song.viz.view import pick_view

    probes = ProbeGrid.from_json(read_usd_lighting(root / "scene_flat.usda"))
    scene = scene_gaussians(root / "3dgs_compressed.ply")
    rng = np.random.default_rng(0)
    avatars = [_Avatar(None, None, None, rng.normal(size=(40_000, 1, 3)).astype(np.float32) * 0.5) for _ in range(5)]
    x, y, yaw = pick_view(root, HFOV)
    roots = np.array([[x + 2 + k * 0.5, y + 0.3 * k] for k in range(5)])
    camera = robot_camera(x, y, yaw, CAMERA_HEIGHT, HFOV, 320, 240)
    render([scene], camera)
    shade, frame = [], []
    for step in range(frames):
        start = time.perf_counter()
        factors = probe_irradiance(probes, roots + 0.05 * step) / math.pi * 2.0**probes.exposure_ev
        for avatar, f in zip(avatars, factors, strict=True):
            avatar.shaded(f)
        contact_shadows(roots)
        shade.append(time.perf_counter() - start)
        start = time.perf_counter()
        render([scene], camera)
        frame.append(time.perf_counter() - start)
    s, f = float(np.median(shade)) * 1e3, float(np.median(frame)) * 1e3
    return {"shade_5_avatars_ms": round(s, 2), "frame_320x240_ms": round(f, 1), "share_of_frame": round(s / f, 4)}


def before_after(out: Path, scenes=("office_0000", "restaurant_0004", "library_0006", "procthor_house_6",
                                     "procthor_house_19")) -> Path:  # fmt: skip
    """A JPEG grid: each scene's first-person view unlit (left) and lit (right), same pose, 480×320."""
    import shutil

    import cv2

    from song.datasets.scenes.splat import dress_package
    from song.render import render, robot_camera
    from song.runtime.vision import scene_gaussians
    from song.viz.view import pick_view

    rows = []
    for name in scenes:
        root = out.parent / "before-after" / name
        if root.exists():
            shutil.rmtree(root)
        shutil.copytree(ROOT / "datasets" / "sample_scenes" / name, root)
        pair = []
        for light in (False, True):
            dress_package(root, light=light)
            if not pair:
                pose = pick_view(root, HFOV)
            camera = robot_camera(*pose, CAMERA_HEIGHT, HFOV, 480, 320)
            pair.append(render(scene_gaussians(root / "3dgs_compressed.ply"), camera, background=(0, 0, 0)).rgb)
        rows.append(np.hstack(pair))
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), np.vstack(rows)[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 88])
    return out


def compare(song: np.ndarray, cycles: np.ndarray) -> dict:
    """Pearson correlation of log-luminance and median |ΔY| / Y_cycles of one view."""
    ys, yc = luminance(song), luminance(cycles)
    eps = 1e-3
    a, b = np.log(ys + eps).ravel(), np.log(yc + eps).ravel()
    corr = float(np.corrcoef(a, b)[0, 1])
    rel = np.abs(ys - yc) / np.maximum(yc, eps)
    return {"log_luminance_pearson": round(corr, 4), "median_rel_luminance_error": round(float(np.median(rel)), 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-lighting")
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--size", default="240x180")
    parser.add_argument("--views", type=int, default=5)
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--before-after", type=Path, help="only draw the unlit/lit grid of five scenes to this JPEG")
    args = parser.parse_args()
    if args.before_after:
        emit({"before_after": str(before_after(args.before_after))})
        return
    import shutil

    import cv2

    from song.datasets.scenes.lighting import tone
    from song.datasets.scenes.splat import dress_package

    size = tuple(int(v) for v in args.size.split("x"))
    args.out.mkdir(parents=True, exist_ok=True)
    python = ensure_cycles()
    units = calibrate(python, args.out, args.samples)
    rows, per_scene = [], {}
    for name in args.scenes:
        root = args.out / "scenes" / name
        if root.exists():
            shutil.rmtree(root)
        shutil.copytree(ROOT / "datasets" / "sample_scenes" / name, root)
        for _ in range(2):  # interleaved; the second round is warm (compiled kernels loaded)
            start = time.perf_counter()
            dress_package(root, light=False)
            unlit_s = time.perf_counter() - start
            start = time.perf_counter()
            dress_package(root)
            lit_s = time.perf_counter() - start
        views = _views(root, args.views)
        job, meshes, song_images, seconds, count, fourth, exposure = scene_job(root, views, size, args.samples, units)
        start = time.perf_counter()
        cycles_images = [tone(img, exposure) for img in _run_cycles(python, args.out / "cycles" / name, job, meshes)]
        cycles_seconds = time.perf_counter() - start
        for i, (a, b) in enumerate(zip(song_images, cycles_images, strict=True)):
            rows.append({"scene": name, "view": i, **compare(a, b)})
        grid = np.vstack([np.hstack(song_images), np.hstack(cycles_images)])
        cv2.imwrite(
            str(args.out / f"compare_{name}.png"), (np.clip(grid, 0, 1)[..., ::-1] * 255).round().astype(np.uint8)
        )
        per_scene[name] = {
            "gaussians": count, "splat_unlit_s": round(unlit_s, 3), "splat_lit_s": round(lit_s, 3),
            "splat_lit_s_per_million": round(lit_s / count * 1e6, 3),
            "bake_s_per_million": round((lit_s - unlit_s) / count * 1e6, 3),
            "beyond_third_bounce_median_share": round(fourth, 4), "lights": len(job["lights"]),
            "exposure_ev": exposure, "cycles_s": round(cycles_seconds, 1),
        }  # fmt: skip
    avatar_cost = avatar_light_cost(args.out / "scenes" / args.scenes[0])
    corr = [r["log_luminance_pearson"] for r in rows]
    err = [r["median_rel_luminance_error"] for r in rows]
    emit(
        {
            "reference": f"Blender Cycles (bpy {BPY_VERSION}), {args.samples} spp, denoised",
            "size": list(size),
            "units_blender_w_per_song_w": units,
            "views": rows,
            "scenes": per_scene,
            "avatar_light_cost": avatar_cost,
            "pass_correlation": sum(c >= 0.85 for c in corr),
            "pass_error": sum(e <= 0.15 for e in err),
            "total_views": len(rows),
            "min_correlation": min(corr),
            "max_error": max(err),
        }
    )


if __name__ == "__main__":
    main()
