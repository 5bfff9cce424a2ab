"""The reference twin of ``song.datasets.scenes.usd.write_usd_proxy``: the same proxy, authored through USD's
schema classes (``UsdGeom``, ``UsdPhysics``, ``UsdShade``, ``UsdSemantics``, ``UsdLux``) on a stage.

The product writes the layer's specs directly (much faster); this twin is what those specs must equal.
"""

from __future__ import annotations

import math
import re

import numpy as np

from song.datasets.scenes.usd import DRESSING_KEY, LIGHTING_KEY, ProxyBox, ProxyMesh, _identifier, box_mesh


def _define_mesh(stage, prim_path: str, mesh: ProxyMesh):
    from pxr import UsdGeom, Vt

    points = np.asarray(mesh.vertices, dtype=np.float32)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    prim = UsdGeom.Mesh.Define(stage, prim_path)
    prim.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points))
    prim.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
    prim.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.ravel().tolist()))
    prim.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    prim.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([points.min(axis=0), points.max(axis=0)])))
    return prim


def _material(stage, looks: dict, name: str):
    from pxr import Gf, Sdf, UsdShade

    from song.datasets.scenes.materials import material_of, srgb_to_linear

    if name not in looks:
        if not looks:
            stage.DefinePrim("/World/Looks", "Scope")
        path = f"/World/Looks/{_identifier(name, set())}"
        look = UsdShade.Material.Define(stage, path)
        shader = UsdShade.Shader.Define(stage, f"{path}/surface")
        shader.CreateIdAttr("UsdPreviewSurface")
        albedo = material_of(name)
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(
            Gf.Vec3f(*srgb_to_linear(albedo.base).tolist())
        )
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.4 if albedo.texture == "metal" else 0.8)
        shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
        look.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        looks[name] = look
    return looks[name]


def _decorate(stage, looks: dict, prim, mesh: ProxyMesh, collider: bool) -> None:
    from pxr import UsdPhysics, UsdSemantics, UsdShade

    usd_prim = prim.GetPrim()
    if collider:
        UsdPhysics.CollisionAPI.Apply(usd_prim)
        approximation = UsdPhysics.Tokens.convexHull if mesh.convex else UsdPhysics.Tokens.none
        UsdPhysics.MeshCollisionAPI.Apply(usd_prim).CreateApproximationAttr(approximation)
    if mesh.material:
        UsdShade.MaterialBindingAPI.Apply(usd_prim).Bind(_material(stage, looks, mesh.material))
    if mesh.label:
        UsdSemantics.LabelsAPI.Apply(usd_prim, "class").CreateLabelsAttr([mesh.label])


def _define_lights(stage, lights, used: set[str]) -> None:
    from pxr import Gf, Sdf, UsdGeom, UsdLux

    UsdGeom.Scope.Define(stage, "/World/lights")
    for light in lights:
        path = f"/World/lights/{_identifier(light.id, used)}"
        if light.kind == "rect":
            prim = UsdLux.RectLight.Define(stage, path)
            prim.CreateWidthAttr(float(light.size[0]))
            prim.CreateHeightAttr(float(light.size[1]))
            u, v, n = light.frame()
            x, y, z = u, -v, -n
            intensity = light.radiance
        else:
            prim = UsdLux.SphereLight.Define(stage, path)
            prim.CreateRadiusAttr(float(light.radius))
            x, y, z = np.eye(3)
            intensity = light.power_w / (4 * math.pi) / (math.pi * max(light.radius, 1e-3) ** 2)
        matrix = Gf.Matrix4d(
            *x.tolist(), 0.0, *y.tolist(), 0.0, *z.tolist(), 0.0, *[float(c) for c in light.position], 1.0
        )
        UsdGeom.Xformable(prim).AddTransformOp().Set(matrix)
        prim.CreateIntensityAttr(float(intensity))
        prim.CreateColorAttr(Gf.Vec3f(*[float(c) for c in light.colour]))
        prim.CreateNormalizeAttr(False)
        usd_prim = prim.GetPrim()
        usd_prim.CreateAttribute("song:role", Sdf.ValueTypeNames.Token).Set(light.role)
        usd_prim.CreateAttribute("song:powerW", Sdf.ValueTypeNames.Float).Set(float(light.power_w))


def usd_proxy_text(solids, surfaces=(), dressing_json=None, rooms=(), lights=(), lighting_json=None) -> str:
    """The text ``write_usd_proxy`` must write for these arguments (the same, in the same order)."""
    from pxr import Gf, Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    metadata = {k: v for k, v in {DRESSING_KEY: dressing_json, LIGHTING_KEY: lighting_json}.items() if v is not None}
    if metadata:
        stage.GetRootLayer().customLayerData = metadata
    physics = UsdPhysics.Scene.Define(stage, "/World/physicsScene")
    physics.CreateGravityDirectionAttr(Gf.Vec3f(0.0, 0.0, -1.0))
    physics.CreateGravityMagnitudeAttr(9.81)
    looks: dict = {}
    UsdGeom.Scope.Define(stage, "/World/collision")
    used: set[str] = set()
    for index, solid in enumerate(solids):
        mesh = box_mesh(index, solid) if isinstance(solid, ProxyBox) else solid
        prim = _define_mesh(stage, f"/World/collision/{_identifier(mesh.name, used)}", mesh)
        _decorate(stage, looks, prim, mesh, collider=True)
    if surfaces:
        UsdGeom.Scope.Define(stage, "/World/surfaces")
        for mesh in surfaces:
            prim = _define_mesh(stage, f"/World/surfaces/{_identifier(mesh.name, used)}", mesh)
            _decorate(stage, looks, prim, mesh, collider=False)
    if rooms:
        UsdGeom.Scope.Define(stage, "/World/rooms")
        for mesh in rooms:
            prim = _define_mesh(stage, f"/World/rooms/{_identifier(mesh.name, used)}", mesh)
            prim.CreatePurposeAttr(UsdGeom.Tokens.guide)
            _decorate(stage, looks, prim, mesh, collider=False)
    if lights:
        _define_lights(stage, lights, used)
    text = stage.GetRootLayer().ExportToString()
    return re.sub(r'\n    doc = "[^"]*"\n', "\n", text)
