"""Render a SONG lighting job with Blender Cycles (runs in the benchmark's own ``bpy`` environment).

    <bpy-env>/bin/python benchmarks/_cycles_render.py JOB_DIR

``JOB_DIR/job_input.json`` lists the meshes (``meshes.npz``: ``v<k>`` vertices, ``f<k>`` triangles, one per
material), their linear albedos, the lights (SONG's ``lights.json`` entries), the sample count and
the views (camera position, yaw, horizontal field of view, size); each view is written to
``JOB_DIR/view_<i>.exr`` and ``view_<i>.npy`` (float32 RGB, top row first) as linear radiance (the benchmark applies the exposure and the sRGB
transfer, as SONG's baker does). Light units follow ``job["units"]``: factors that turn SONG's
watts into Blender's (measured by the benchmark's calibration views).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix


def _reset() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _material(name: str, albedo) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*albedo, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0  # Lambertian
    out = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def _mesh(name: str, vertices: np.ndarray, faces: np.ndarray, material) -> None:
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices.tolist(), [], faces.tolist())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.data.materials.append(material)
    bpy.context.scene.collection.objects.link(obj)


def _light(spec: dict, units: dict) -> None:
    u = np.asarray(spec["u_axis"], dtype=float)
    n = np.asarray(spec["normal"], dtype=float)
    n /= np.linalg.norm(n)
    u -= (u @ n) * n
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    if spec["kind"] == "rect":
        data = bpy.data.lights.new(spec["id"], "AREA")
        data.shape = "RECTANGLE"
        data.size, data.size_y = spec["size"]
        data.energy = spec["power_w"] * units["area"]
        # Blender's area light emits along its local −Z: local axes (u, −v, −n)
        x, y, z = u, -v, -n
    else:
        data = bpy.data.lights.new(spec["id"], "POINT")
        data.shadow_soft_size = spec["radius"]
        if hasattr(data, "use_soft_falloff"):
            data.use_soft_falloff = False
        data.energy = spec["power_w"] * units["point"]
        x, y, z = np.eye(3)
    data.color = spec["colour"]
    obj = bpy.data.objects.new(spec["id"], data)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, spec["position"]
    obj.matrix_world = Matrix(m.tolist())
    obj.visible_camera = True
    bpy.context.scene.collection.objects.link(obj)


def _camera(view: dict) -> bpy.types.Object:
    data = bpy.data.cameras.new("camera")
    data.sensor_fit = "HORIZONTAL"
    data.angle = math.radians(view["hfov_deg"])
    data.clip_start = 0.01
    obj = bpy.data.objects.new("camera", data)
    obj.location = view["position"]
    obj.rotation_euler = (math.pi / 2, 0.0, view["yaw"] - math.pi / 2)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def main(job_dir: Path) -> None:
    job = json.loads((job_dir / "job_input.json").read_text())
    arrays = np.load(job_dir / "meshes.npz")
    _reset()
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = job["samples"]
    scene.cycles.use_denoising = job.get("denoise", True)
    scene.cycles.max_bounces = 12
    scene.cycles.diffuse_bounces = 12
    scene.cycles.seed = 0
    scene.cycles.sample_clamp_indirect = 0.0
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.render.image_settings.file_format = "OPEN_EXR"  # linear, scene-referred: exposure and tone applied after
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "32"
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    for k, (name, albedo) in enumerate(zip(job["materials"], job["albedos"], strict=True)):
        _mesh(name, arrays[f"v{k}"], arrays[f"f{k}"], _material(name, albedo))
    for spec in job["lights"]:
        _light(spec, job["units"])
    for i, view in enumerate(job["views"]):
        camera = _camera(view)
        scene.camera = camera
        scene.render.resolution_x, scene.render.resolution_y = view["size"]
        scene.render.resolution_percentage = 100
        scene.render.filepath = str(job_dir / f"view_{i}.exr")
        bpy.ops.render.render(write_still=True)
        image = bpy.data.images.load(scene.render.filepath)
        w, h = view["size"]
        pixels = np.array(image.pixels[:], dtype=np.float32).reshape(h, w, 4)[::-1, :, :3]
        np.save(job_dir / f"view_{i}.npy", pixels)  # linear RGB, top row first
        bpy.data.images.remove(image)
        bpy.data.objects.remove(camera)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
