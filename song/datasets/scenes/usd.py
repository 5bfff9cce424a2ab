"""USD proxy ``scene_flat.usda``: Z-up, metres.

``/World/collision`` holds the obstacles as ``UsdGeom.Mesh`` prims -- walls, furniture parts, lintels --
each a closed solid; ``/World/surfaces`` holds the floor and the ceiling (flat meshes). For simulators
(Isaac Sim / Isaac Lab read it as it is): every obstacle is a static collider (``UsdPhysics.CollisionAPI``,
no rigid body; convex parts approximated by their convex hull, walls -- not convex -- as triangle
meshes), ``/World/physicsScene`` sets gravity along -Z, every mesh with a known material is bound to a
``UsdPreviewSurface`` under ``/World/Looks`` whose diffuse colour is the material's base albedo (the
colour the Gaussians are textured around) converted to linear, and every mesh with a known class
carries ``UsdSemantics.LabelsAPI`` labels (taxonomy ``class``: the semantic map's category, ``wall``,
``floor``, ``ceiling``, ``door``). ``/World/rooms`` holds one flat, unrendered (purpose ``guide``) mesh per
semantic-map region labelled with its room type. A
:class:`ProxyBox` (a vertical prism over a CCW footprint) becomes 8 points and 12 triangles; any other
solid comes as a :class:`ProxyMesh`. The layer's ``customLayerData`` may carry ``song_dressing``: the
JSON of :class:`song.datasets.scenes.dressing.DressingHints` (what the scene's source knew: openings,
materials, ceiling height). usd-core (``pxr``) is imported lazily; without it a
:class:`MissingDependencyError` names the extra.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song.errors import FormatError, MissingDependencyError
from song.util import write_text_atomic

DRESSING_KEY = "song_dressing"
LIGHTING_KEY = "song_lighting"
# two triangles per side face + top + bottom, for points 0..3 at z_min and 4..7 at z_max
PRISM_FACES = np.array(
    [
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
        [4, 5, 6],
        [4, 6, 7],
        [0, 2, 1],
        [0, 3, 2],
    ]
)


@dataclass(frozen=True)
class ProxyBox:
    """A vertical prism: a wall segment or a furniture box.

    Attributes:
        name: prim name (a valid USD identifier is derived from it).
        footprint: (4, 2) float64 CCW corners in the x-y plane, metres.
        z_min: bottom height, metres.
        z_max: top height, metres.
    """

    name: str
    footprint: np.ndarray
    z_min: float
    z_max: float


@dataclass(frozen=True)
class ProxyMesh:
    """A mesh: name, vertices (V, 3) float64, triangle faces (F, 3) int.

    ``material`` (a :data:`song.datasets.scenes.materials.MATERIALS` name or ``paint:#rrggbb``), ``label``
    (a semantic class) and ``convex`` are written to the proxy when given; meshes read back carry their
    material.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    material: str | None = None
    label: str | None = None
    convex: bool = False


def _pxr():
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt
    except ImportError as exc:
        raise MissingDependencyError("pxr", "usd") from exc
    return Sdf, Usd, UsdGeom, Vt


def _identifier(name: str, used: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_]", "_", name) or "prim"
    if base[0].isdigit():
        base = f"_{base}"
    candidate, k = base, 1
    while candidate in used:
        k += 1
        candidate = f"{base}_{k}"
    used.add(candidate)
    return candidate


def _check_box(index: int, box: ProxyBox) -> np.ndarray:
    fp = np.asarray(box.footprint, dtype=np.float64)
    if fp.shape != (4, 2) or not np.isfinite(fp).all() or not np.isfinite([box.z_min, box.z_max]).all():
        raise ValueError(f"boxes[{index}] '{box.name}': footprint must be (4, 2) finite metres, heights finite")
    if box.z_max <= box.z_min:
        raise ValueError(f"boxes[{index}] '{box.name}': z_max {box.z_max} must exceed z_min {box.z_min}")
    return fp


def box_mesh(index: int, box: ProxyBox) -> ProxyMesh:
    """The closed triangle mesh of a :class:`ProxyBox` (outward faces)."""
    fp = _check_box(index, box)
    points = np.vstack([np.column_stack([fp, np.full(4, box.z_min)]), np.column_stack([fp, np.full(4, box.z_max)])])
    return ProxyMesh(box.name, points, PRISM_FACES.copy())


# the API schemas a mesh carries, in the order USD's schema classes apply them
_COLLIDER_SCHEMAS = ("PhysicsCollisionAPI", "PhysicsMeshCollisionAPI")
_MATERIAL_SCHEMA = "MaterialBindingAPI"
_LABELS_SCHEMA = "SemanticsLabelsAPI:class"


class _LayerWriter:
    """Authors the proxy's specs straight into an ``Sdf.Layer``.

    The layer holds exactly the specs that USD's schema classes (``UsdGeom.Mesh``, ``UsdPhysics``,
    ``UsdShade``, ``UsdSemantics.LabelsAPI``, ``UsdLux``) would author -- ``tests/datasets/scenes/test_usd.py``
    holds the text equal, byte for byte, to a twin written through those classes -- at a fraction of the
    cost: a stage reacts to every edit, and a scene has hundreds of meshes.
    """

    def __init__(self, Sdf, Vt) -> None:
        from pxr import Gf

        self.Sdf, self.Vt, self.Gf = Sdf, Vt, Gf
        self.layer = Sdf.Layer.CreateAnonymous(".usda")
        self.prims: dict[str, object] = {}
        self.looks: set[str] = set()

    def prim(self, path: str, type_name: str):
        parent, name = path.rsplit("/", 1)
        owner = self.prims[parent] if parent else self.layer
        spec = self.Sdf.PrimSpec(owner, name, self.Sdf.SpecifierDef, type_name)
        self.prims[path] = spec
        return spec

    def attribute(self, prim, name: str, type_name, value=None, uniform: bool = False, custom: bool = False):
        variability = self.Sdf.VariabilityUniform if uniform else self.Sdf.VariabilityVarying
        spec = self.Sdf.AttributeSpec(prim, name, type_name, variability, custom)
        if value is not None:
            spec.default = value
        return spec

    def relationship(self, prim, name: str, target: str) -> None:
        self.Sdf.RelationshipSpec(prim, name, False).targetPathList.explicitItems = [self.Sdf.Path(target)]

    def mesh(self, prim_path: str, mesh: ProxyMesh, collider: bool, guide: bool = False) -> None:
        Sdf, Vt, types = self.Sdf, self.Vt, self.Sdf.ValueTypeNames
        points = np.asarray(mesh.vertices, dtype=np.float32)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        if len(points) == 0 or not np.isfinite(points).all() or len(faces) == 0:
            raise ValueError(f"mesh '{mesh.name}': needs finite points and at least one face")
        look = self.material(mesh.material) if mesh.material else None
        prim = self.prim(prim_path, "Mesh")
        schemas = [*(_COLLIDER_SCHEMAS if collider else ()), *((_MATERIAL_SCHEMA,) if look else ())]
        schemas += [_LABELS_SCHEMA] if mesh.label else []
        if schemas:
            prim.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=schemas))
        self.attribute(prim, "points", types.Point3fArray, Vt.Vec3fArray.FromNumpy(points))
        self.attribute(
            prim, "faceVertexCounts", types.IntArray, Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32))
        )
        self.attribute(prim, "faceVertexIndices", types.IntArray, Vt.IntArray.FromNumpy(faces.ravel().astype(np.int32)))
        self.attribute(prim, "subdivisionScheme", types.Token, "none", uniform=True)
        bounds = np.stack([points.min(axis=0), points.max(axis=0)])
        self.attribute(prim, "extent", types.Float3Array, Vt.Vec3fArray.FromNumpy(bounds))
        if guide:
            self.attribute(prim, "purpose", types.Token, "guide", uniform=True)
        if collider:
            self.attribute(
                prim, "physics:approximation", types.Token, "convexHull" if mesh.convex else "none", uniform=True
            )
        if look:
            self.relationship(prim, "material:binding", look)
        if mesh.label:
            self.attribute(prim, "semantics:labels:class", types.TokenArray, Vt.TokenArray([mesh.label]))

    def material(self, name: str) -> str:
        """The path of material ``name``'s ``UsdPreviewSurface`` under ``/World/Looks``, made on first use."""
        from song.datasets.scenes.materials import material_of, srgb_to_linear

        path = f"/World/Looks/{_identifier(name, set())}"
        if path in self.looks:
            return path
        if not self.looks:
            self.prim("/World/Looks", "Scope")
        self.looks.add(path)
        types, Gf = self.Sdf.ValueTypeNames, self.Gf
        look = self.prim(path, "Material")
        output = self.attribute(look, "outputs:surface", types.Token)
        output.connectionPathList.explicitItems = [self.Sdf.Path(f"{path}/surface.outputs:surface")]
        shader = self.prim(f"{path}/surface", "Shader")
        self.attribute(shader, "info:id", types.Token, "UsdPreviewSurface", uniform=True)
        albedo = material_of(name)
        self.attribute(shader, "inputs:diffuseColor", types.Color3f, Gf.Vec3f(*srgb_to_linear(albedo.base).tolist()))
        self.attribute(shader, "inputs:roughness", types.Float, 0.4 if albedo.texture == "metal" else 0.8)
        self.attribute(shader, "inputs:metallic", types.Float, 0.0)
        self.attribute(shader, "outputs:surface", types.Token)
        return path

    def lights(self, lights, used: set[str]) -> None:
        """``RectLight`` (local −Z along the light's normal) and ``SphereLight`` prims, normalised off.

        ``intensity`` is the emitted radiance (a rect light's, or a sphere's surface); ``song:role`` and
        ``song:powerW`` keep SONG's description (``lights.json`` is the file the baker reads).
        """
        import math

        types, Gf = self.Sdf.ValueTypeNames, self.Gf
        self.prim("/World/lights", "Scope")
        for light in lights:
            path = f"/World/lights/{_identifier(light.id, used)}"
            if light.kind == "rect":
                prim = self.prim(path, "RectLight")
                self.attribute(prim, "inputs:width", types.Float, float(light.size[0]))
                self.attribute(prim, "inputs:height", types.Float, float(light.size[1]))
                u, v, n = light.frame()
                x, y, z = u, -v, -n  # the light's local frame: it emits along −Z
                intensity = light.radiance
            else:
                prim = self.prim(path, "SphereLight")
                self.attribute(prim, "inputs:radius", types.Float, float(light.radius))
                x, y, z = np.eye(3)
                intensity = light.power_w / (4 * math.pi) / (math.pi * max(light.radius, 1e-3) ** 2)
            matrix = Gf.Matrix4d(
                *x.tolist(), 0.0, *y.tolist(), 0.0, *z.tolist(), 0.0, *[float(c) for c in light.position], 1.0
            )
            self.attribute(prim, "xformOp:transform", types.Matrix4d, matrix)
            self.attribute(
                prim, "xformOpOrder", types.TokenArray, self.Vt.TokenArray(["xformOp:transform"]), uniform=True
            )
            self.attribute(prim, "inputs:intensity", types.Float, float(intensity))
            self.attribute(prim, "inputs:color", types.Color3f, Gf.Vec3f(*[float(c) for c in light.colour]))
            self.attribute(prim, "inputs:normalize", types.Bool, False)
            self.attribute(prim, "song:role", types.Token, light.role, custom=True)
            self.attribute(prim, "song:powerW", types.Float, float(light.power_w), custom=True)


def write_usd_proxy(
    path: str | Path,
    solids: list[ProxyBox | ProxyMesh],
    surfaces: list[ProxyMesh] = (),
    dressing_json: str | None = None,
    rooms: list[ProxyMesh] = (),
    lights: list = (),
    lighting_json: str | None = None,
) -> None:
    """Write ``scene_flat.usda`` (metersPerUnit 1, upAxis Z), atomically.

    The text is exported from an in-memory layer and written with an atomic rename; it depends only
    on the inputs (names, float32 points, faces, the hints text), so the same scene gives the same bytes.
    Prim names are USD identifiers derived from the given names, made unique with ``_2``, ``_3`` ...

    Args:
        path: the file to write.
        solids: obstacles (``/World/collision``): boxes or closed meshes.
        surfaces: floor and ceiling meshes (``/World/surfaces``).
        rooms: one flat labelled mesh per room (``/World/rooms``, purpose ``guide``).
        dressing_json: :class:`~song.datasets.scenes.dressing.DressingHints` JSON for the layer metadata.
        lights: :class:`~song.datasets.scenes.lights.Light` s, written as ``UsdLux`` prims (``/World/lights``).
        lighting_json: the baked :class:`~song.datasets.scenes.lighting.ProbeGrid` JSON for the layer metadata.

    Raises:
        MissingDependencyError: usd-core is not installed.
        ValueError: a box is not a (4, 2) finite footprint with z_max > z_min, or a mesh is empty.
    """
    Sdf, Usd, UsdGeom, Vt = _pxr()
    writer = _LayerWriter(Sdf, Vt)
    layer = writer.layer
    with Sdf.ChangeBlock():
        root = layer.pseudoRoot
        root.SetInfo("upAxis", "Z")
        root.SetInfo("metersPerUnit", 1.0)
        metadata = {DRESSING_KEY: dressing_json, LIGHTING_KEY: lighting_json}
        metadata = {k: v for k, v in metadata.items() if v is not None}
        if metadata:
            layer.customLayerData = metadata
        writer.prim("/World", "Xform")
        layer.defaultPrim = "World"
        physics = writer.prim("/World/physicsScene", "PhysicsScene")
        types = Sdf.ValueTypeNames
        writer.attribute(physics, "physics:gravityDirection", types.Vector3f, writer.Gf.Vec3f(0.0, 0.0, -1.0))
        writer.attribute(physics, "physics:gravityMagnitude", types.Float, 9.81)
        writer.prim("/World/collision", "Scope")
        used: set[str] = set()
        for index, solid in enumerate(solids):
            mesh = box_mesh(index, solid) if isinstance(solid, ProxyBox) else solid
            writer.mesh(f"/World/collision/{_identifier(mesh.name, used)}", mesh, collider=True)
        for scope, meshes, guide in (("surfaces", surfaces, False), ("rooms", rooms, True)):
            if meshes:
                writer.prim(f"/World/{scope}", "Scope")
                for mesh in meshes:
                    writer.mesh(f"/World/{scope}/{_identifier(mesh.name, used)}", mesh, collider=False, guide=guide)
        if lights:
            writer.lights(lights, used)
    write_text_atomic(path, layer.ExportToString())


def read_usd_lighting(path: str | Path) -> str | None:
    """The baked probe grid's JSON from a proxy's layer metadata, or None (an unlit scene)."""
    return _layer_text(path, LIGHTING_KEY)


def read_usd_dressing(path: str | Path) -> str | None:
    """The ``song_dressing`` JSON text of a proxy's layer metadata, or None when it has none."""
    return _layer_text(path, DRESSING_KEY)


def _layer_text(path: str | Path, key: str) -> str | None:
    Sdf, Usd, UsdGeom, Vt = _pxr()
    layer = Sdf.Layer.FindOrOpen(str(path))
    if layer is None:
        raise FormatError(path, "", "not a readable USD layer")
    value = dict(layer.customLayerData).get(key)
    return str(value) if value is not None else None


def read_usd_surfaces(path: str | Path) -> list[ProxyMesh]:
    """The meshes under ``/World/surfaces`` (floor and ceiling), faces triangulated; [] when absent."""
    Sdf, Usd, UsdGeom, Vt = _pxr()
    stage = Usd.Stage.Open(str(path))
    root = stage.GetPrimAtPath("/World/surfaces") if stage is not None else None
    if root is None or not root.IsValid():
        return []
    return [_read_mesh(Path(path), prim, UsdGeom.Mesh(prim)) for prim in root.GetChildren() if prim.IsA(UsdGeom.Mesh)]


def read_usd_proxy(path: str | Path) -> list[ProxyMesh]:
    """The meshes under ``/World/collision``, faces fan-triangulated.

    Returns:
        One :class:`ProxyMesh` per ``UsdGeom.Mesh`` child, in prim order: vertices (V, 3) float64
        metres (Z up), faces (F, 3) int64 indices into vertices.

    Raises:
        MissingDependencyError: usd-core is not installed.
        FormatError: missing or unreadable file, wrong stage metadata, or a malformed mesh, naming
            the prim and attribute.
    """
    Sdf, Usd, UsdGeom, Vt = _pxr()
    from pxr import Tf

    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "", "file is missing")
    try:
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as exc:
        reason = " ".join(str(exc).split()).split("' : ")[-1][:160]
        raise FormatError(path, "", f"not a readable USD layer ({reason})") from exc
    if stage is None:
        raise FormatError(path, "", "not a readable USD stage")
    if UsdGeom.GetStageUpAxis(stage) != UsdGeom.Tokens.z:
        raise FormatError(path, "upAxis", f"is '{UsdGeom.GetStageUpAxis(stage)}', expected 'Z'")
    if UsdGeom.GetStageMetersPerUnit(stage) != 1.0:
        raise FormatError(path, "metersPerUnit", f"is {UsdGeom.GetStageMetersPerUnit(stage)}, expected 1")
    root = stage.GetPrimAtPath("/World/collision")
    if not root.IsValid():
        raise FormatError(path, "/World/collision", "prim is missing")
    return [_read_mesh(path, prim, UsdGeom.Mesh(prim)) for prim in root.GetChildren() if prim.IsA(UsdGeom.Mesh)]


def _read_mesh(path: Path, prim, mesh) -> ProxyMesh:
    where = str(prim.GetPath())
    points = np.asarray(mesh.GetPointsAttr().Get() or [], dtype=np.float64).reshape(-1, 3)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    if len(points) == 0 or not np.isfinite(points).all():
        raise FormatError(path, f"{where}.points", "must be a non-empty list of finite points")
    if (counts < 3).any() or counts.sum() != len(indices):
        raise FormatError(
            path, f"{where}.faceVertexCounts", f"sum {counts.sum()} ≠ {len(indices)} indices or a face < 3"
        )
    if len(indices) and (indices.min() < 0 or indices.max() >= len(points)):
        raise FormatError(path, f"{where}.faceVertexIndices", f"index out of range for {len(points)} points")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    faces = [
        np.column_stack([np.full(c - 2, indices[s]), indices[s + 1 : s + c - 1], indices[s + 2 : s + c]])
        for s, c in zip(starts, counts, strict=True)
    ]
    tri = np.concatenate(faces) if faces else np.zeros((0, 3), dtype=np.int64)
    return ProxyMesh(prim.GetName(), points, tri.astype(np.int64), material=_bound_material(prim))


def _bound_material(prim) -> str | None:
    """The name of the material bound to a prim when it is one of ours (a known material name), else None."""
    from pxr import UsdShade

    from song.datasets.scenes.materials import MATERIALS

    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    name = material.GetPrim().GetName() if material else ""
    if name in MATERIALS:
        return name
    if name.startswith("paint__") and len(name) == 13:  # "paint:#rrggbb" as a USD identifier
        return "paint:#" + name[7:]
    return None
