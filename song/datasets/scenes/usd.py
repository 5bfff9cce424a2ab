"""USD collision proxy ``scene_flat.usda`` (DESIGN §4.3): Z-up, metres, /World/collision meshes.

Each :class:`ProxyBox` (a wall segment or a furniture box: a vertical prism over a CCW footprint)
becomes one ``UsdGeom.Mesh`` with 8 points and 12 triangles under ``/World/collision``. usd-core
(``pxr``) is imported lazily; without it a :class:`MissingDependencyError` names the extra.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song.errors import FormatError, MissingDependencyError
from song.util import write_text_atomic

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
    """A mesh read back from the proxy: name, vertices (V, 3) float64, triangle faces (F, 3) int."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray


def _pxr():
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt
    except ImportError as exc:
        raise MissingDependencyError("pxr (usd-core)", "usd") from exc
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


def write_usd_proxy(path: str | Path, boxes: list[ProxyBox]) -> None:
    """Write ``scene_flat.usda`` (metersPerUnit 1, upAxis Z) with one mesh per box, atomically."""
    Sdf, Usd, UsdGeom, Vt = _pxr()
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    UsdGeom.Scope.Define(stage, "/World/collision")
    used: set[str] = set()
    for box in boxes:
        fp = np.asarray(box.footprint, dtype=np.float64)
        points = np.vstack([np.column_stack([fp, np.full(4, box.z_min)]), np.column_stack([fp, np.full(4, box.z_max)])])
        mesh = UsdGeom.Mesh.Define(stage, f"/World/collision/{_identifier(box.name, used)}")
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(PRISM_FACES)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(PRISM_FACES.ravel().tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    text = stage.GetRootLayer().ExportToString()
    text = re.sub(r'\n    doc = "[^"]*"\n', "\n", text)  # no tool banner: bytes depend on the boxes only
    write_text_atomic(path, text)


def read_usd_proxy(path: str | Path) -> list[ProxyMesh]:
    """The meshes under ``/World/collision`` (triangulated fans for non-triangle faces)."""
    Sdf, Usd, UsdGeom, Vt = _pxr()
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "", "file is missing")
    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise FormatError(path, "", "not a readable USD stage")
    if UsdGeom.GetStageUpAxis(stage) != UsdGeom.Tokens.z or UsdGeom.GetStageMetersPerUnit(stage) != 1.0:
        raise FormatError(path, "upAxis", "expected upAxis Z and metersPerUnit 1")
    root = stage.GetPrimAtPath("/World/collision")
    if not root.IsValid():
        raise FormatError(path, "/World/collision", "prim is missing")
    meshes = []
    for prim in root.GetChildren():
        mesh = UsdGeom.Mesh(prim)
        if not mesh:
            continue
        points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
        counts = list(mesh.GetFaceVertexCountsAttr().Get())
        indices = list(mesh.GetFaceVertexIndicesAttr().Get())
        faces, cursor = [], 0
        for count in counts:
            poly = indices[cursor : cursor + count]
            faces += [[poly[0], poly[i], poly[i + 1]] for i in range(1, count - 1)]
            cursor += count
        meshes.append(ProxyMesh(prim.GetName(), points, np.asarray(faces, dtype=np.int64)))
    return meshes
