"""Scene Gaussians synthesised from a scene's geometry (for scenes without a trained 3DGS).

Every visible surface of the :class:`~song.datasets.scenes.dressing.Dressing` -- floor, walls up to the
ceiling, ceiling, furniture parts, lintels and trims -- is covered with surfels on a jittered grid of
``spacing`` metres: each Gaussian lies on its surface, its rotation aligns its local z with the surface
normal, it is thin along the normal (6 % of the spacing) and σ = 0.6 spacings wide across (neighbours
overlap, so no hole opens even from 0.3 m away, while a surface's edge bleeds only about half a
spacing past the geometry), and near-opaque (opacity 0.993). Faces smaller than the
spacing get proportionally finer samples. Hidden faces (box bottoms on the floor, the back of open
shelves, walls facing other walls) are skipped.

Colour = procedural material texture (:mod:`song.datasets.scenes.materials`) lit by the scene's lights
(:mod:`song.datasets.scenes.lights`, baked by :mod:`song.datasets.scenes.lighting`: shadows, diffuse
bounces, exposure); unlit (``light=False``), a soft directional light from above (0.72 ambient +
0.28·max(0, n·L)) times ambient occlusion -- floors darken within ~25 cm of walls and furniture, walls
near the floor, the ceiling and inside corners, furniture toward the floor and under raised parts
(lit scenes keep this occlusion on their bounced light). Entrances get a closed door just outside
them (a camera would otherwise look out into the void). Gaussians are written in spatial order
(half-metre cells), so the SuperSplat chunks of 256 are compact and a renderer culls them well.
Deterministic in the scene and the seed.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numba as nb
import numpy as np

from song.config import SURFEL_SPACING_M
from song.datasets.scenes.dressing import Dressing, DressingHints, build_dressing
from song.datasets.scenes.furniture import Part
from song.datasets.scenes.materials import texture, variant
from song.datasets.scenes.ply import SH_C0, GaussianCloud
from song.geometry.freespace import clearance_field
from song.util import derive_rng

if TYPE_CHECKING:
    from song.datasets.scenes.lighting import Bake

SPACING_M = SURFEL_SPACING_M  # default surfel spacing (song.config, where the CLI reads it without this module)
WIDTH_FACTOR = 0.6  # in-plane σ as a fraction of the local spacing (no holes from 0.3 m; edges bleed ≈ ½ spacing)
THIN_FACTOR = 0.06  # σ along the normal as a fraction of the local spacing
JITTER = 0.2  # sample positions jitter by this fraction of the spacing
EDGE_FACTOR = 0.7  # an object face's outermost samples: σ across its edge × this (α ≈ 0.5 on the edge, as a true edge)
OPACITY_LOGIT = 5.0  # sigmoid(5) = 0.993
LIGHT = np.array([0.35, 0.5, 0.79]) / np.linalg.norm([0.35, 0.5, 0.79])
AMBIENT, DIFFUSE = 0.72, 0.28
SORT_CELL_M = 0.5


_MATERIAL_CODES: dict[str, int] = {}  # material name → small int, for grouping samples by material
_MATERIAL_NAMES: list[str] = []


def _instance_material(p: Part) -> str:
    """The material variant of a part's object (every part of one object shares it; doors and frames do not vary)."""
    if p.group in ("lintel", "frame", "door") or p.material.startswith("paint:"):
        return p.material
    return variant(p.material, zlib.crc32(p.group.encode()))


def _codes(names) -> np.ndarray:
    """int32 codes of material names (assigned on first sight; only used to group samples)."""
    for name in names:
        if name not in _MATERIAL_CODES:
            _MATERIAL_CODES[name] = len(_MATERIAL_NAMES)
            _MATERIAL_NAMES.append(name)
    return np.array([_MATERIAL_CODES[name] for name in names], dtype=np.int32)


@dataclass
class _Samples:
    """Surface samples before colouring.

    Positions, rotations (wxyz, local z = normal), normals, in-plane scales, texture coordinates,
    material codes (:func:`_codes`), ambient occlusion.
    """

    pos: np.ndarray
    quat: np.ndarray
    n: np.ndarray
    s1: np.ndarray
    s2: np.ndarray
    uv: np.ndarray
    material: np.ndarray
    ao: np.ndarray

    @classmethod
    def concat(cls, items: list[_Samples]) -> _Samples:
        items = [i for i in items if len(i.pos)]
        if not items:
            z = np.zeros((0, 3))
            return cls(
                z, np.zeros((0, 4)), z, np.zeros(0), np.zeros(0), np.zeros((0, 2)), np.zeros(0, np.int32), np.zeros(0)
            )
        return cls(*(np.concatenate([getattr(i, f) for i in items]) for f in cls.__dataclass_fields__))


def _face_grid(lu: np.ndarray, lv: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows of samples :func:`_faces` lays on each rectangle (in its order)."""
    su = np.minimum(spacing, np.maximum(lu / 3, spacing / 4))
    sv = np.minimum(spacing, np.maximum(lv / 3, spacing / 4))
    return np.maximum(1, np.round(lu / su)).astype(np.int64), np.maximum(1, np.round(lv / sv)).astype(np.int64)


def _faces(origin, eu, ev, lu, lv, material, ao_floor, spacing, rng, sharp: bool = True) -> _Samples:
    """Jittered grid samples on F planar rectangles ``origin + u·eu + v·ev`` (u ∈ [0, lu], v ∈ [0, lv]).

    Args:
        origin: (F, 3) corners.
        eu: (F, 3) unit edge direction of u.
        ev: (F, 3) unit edge direction of v (``eu × ev`` is the outward normal).
        lu: (F,) edge lengths along u, m.
        lv: (F,) edge lengths along v, m.
        material: (F,) material names.
        ao_floor: (F,) bool: darken toward the floor (vertical faces standing on it).
        spacing: target sample spacing, m.
        rng: jitter source.
        sharp: the outermost row and column of samples are narrower across the face's edge
            (:data:`EDGE_FACTOR`), so an object's outline does not bleed half a spacing into what lies
            behind it (a desk's legs and a monitor read as wide as they are). Walls keep full samples:
            their edges meet the floor, the ceiling and the other walls.
    """
    f = len(lu)
    if f == 0:
        return _Samples.concat([])
    nu, nv = _face_grid(lu, lv, spacing)
    total = int((nu * nv).sum())
    jitter_u, jitter_v = rng.uniform(-1, 1, total), rng.uniform(-1, 1, total)
    normal_f = np.cross(eu, ev)
    face, u, v, pos, normal, s1, s2 = _face_samples(
        *(np.ascontiguousarray(a, dtype=np.float64) for a in (origin, eu, ev, normal_f, lu, lv)),
        nu, nv, jitter_u, jitter_v, sharp,
    )  # fmt: skip
    ao = np.ones(total)
    standing = ao_floor[face]
    ao[standing] = 1.0 - 0.3 * np.exp(-pos[standing, 2] / 0.15)
    down = normal[:, 2] < -0.5
    ao[down] = 0.6  # undersides (table tops, shelves, lintels) face the floor
    uv = np.column_stack([u + origin[face] @ np.array([1.0, 0.7, 0.3]), v + origin[face, 2]])
    quat = frame_quats(eu, ev, normal_f)[face]  # one rotation per face
    return _Samples(pos, quat, normal, s1, s2, uv, _codes(material)[face], ao)


@nb.njit(cache=True)
def _face_samples(
    origin, eu, ev, normal_f, lu, lv, nu, nv, jitter_u, jitter_v, sharp
):  # pragma: no cover - compiled; twin: _face_samples_reference
    """Each rectangle's jittered grid, row by row (v fastest): face, u, v, position, normal, σ across u and v."""
    n = len(jitter_u)
    face = np.empty(n, dtype=np.int64)
    u_out, v_out, s1, s2 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    pos, normal = np.empty((n, 3)), np.empty((n, 3))
    r = 0
    for f in range(len(lu)):
        du, dv = lu[f] / nu[f], lv[f] / nv[f]
        for i in range(nu[f]):
            for j in range(nv[f]):
                u = (i + 0.5 + JITTER * jitter_u[r]) * du
                v = (j + 0.5 + JITTER * jitter_v[r]) * dv
                face[r], u_out[r], v_out[r] = f, u, v
                for a in range(3):
                    pos[r, a] = origin[f, a] + u * eu[f, a] + v * ev[f, a]
                    normal[r, a] = normal_f[f, a]
                s1[r], s2[r] = WIDTH_FACTOR * du, WIDTH_FACTOR * dv
                if sharp and (i == 0 or i == nu[f] - 1):
                    s1[r] = EDGE_FACTOR * s1[r]
                if sharp and (j == 0 or j == nv[f] - 1):
                    s2[r] = EDGE_FACTOR * s2[r]
                r += 1
    return face, u_out, v_out, pos, normal, s1, s2


def _face_samples_reference(origin, eu, ev, normal_f, lu, lv, nu, nv, jitter_u, jitter_v, sharp):
    """The numpy twin of :func:`_face_samples` (tests)."""
    counts = nu * nv
    face = np.repeat(np.arange(len(lu)), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    i, j = k // nv[face], k % nv[face]
    du, dv = lu[face] / nu[face], lv[face] / nv[face]
    u = (i + 0.5 + JITTER * jitter_u) * du
    v = (j + 0.5 + JITTER * jitter_v) * dv
    pos = origin[face] + u[:, None] * eu[face] + v[:, None] * ev[face]
    s1, s2 = WIDTH_FACTOR * du, WIDTH_FACTOR * dv
    if sharp:
        s1 = np.where((i == 0) | (i == nu[face] - 1), EDGE_FACTOR * s1, s1)
        s2 = np.where((j == 0) | (j == nv[face] - 1), EDGE_FACTOR * s2, s2)
    return face, u, v, pos, normal_f[face], s1, s2


def _box_faces(parts: list[Part]) -> tuple:
    """The visible faces of box parts as arrays for :func:`_faces`."""
    rows = []
    for p in parts:
        c, s = math.cos(p.yaw), math.sin(p.yaw)
        ax, ay, az = np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])
        hx, hy = p.half
        centre = np.array([*p.centre, 0.0])
        corner = centre - hx * ax - hy * ay + p.z0 * az  # the (−x, −y, bottom) corner
        h = p.z1 - p.z0
        on_floor = p.z0 < 0.01
        faces = {
            "top": (corner + h * az, ax, ay, 2 * hx, 2 * hy, False),
            "bottom": (corner + 2 * hy * ay, ax, -ay, 2 * hx, 2 * hy, False),
            "-y": (corner, ax, az, 2 * hx, h, on_floor),
            "+y": (corner + 2 * hx * ax + 2 * hy * ay, -ax, az, 2 * hx, h, on_floor),
            "+x": (corner + 2 * hx * ax, ay, az, 2 * hy, h, on_floor),
            "-x": (corner + 2 * hy * ay, -ay, az, 2 * hy, h, on_floor),
        }
        for name, (o, eu, ev, lu, lv, standing) in faces.items():
            if name not in p.hidden and lu > 1e-4 and lv > 1e-4:
                rows.append((o, eu, ev, lu, lv, _instance_material(p), standing))
    if not rows:
        return (np.zeros((0, 3)),) * 3 + (np.zeros(0),) * 2 + (np.zeros(0, object), np.zeros(0, bool))
    o, eu, ev, lu, lv, m, st = zip(*rows, strict=True)
    return np.array(o), np.array(eu), np.array(ev), np.array(lu), np.array(lv), np.array(m, object), np.array(st)


def _round_parts(parts: list[Part], spacing: float, rng) -> _Samples:
    """Cylinders (side and top) and ellipsoids sampled on their surfaces."""
    out = []
    for p in parts:
        rx, ry = p.half
        cx, cy = p.centre
        if p.kind == "cylinder":
            perimeter = math.pi * (rx + ry)
            na = max(8, int(round(perimeter / spacing)))
            nh = max(1, int(round((p.z1 - p.z0) / spacing)))
            a = (np.arange(na * nh) % na + 0.5) / na * 2 * math.pi
            z = p.z0 + (np.arange(na * nh) // na + 0.5) / nh * (p.z1 - p.z0)
            n = np.column_stack([np.cos(a) / rx, np.sin(a) / ry, np.zeros_like(a)])
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            pos = np.column_stack([cx + rx * np.cos(a), cy + ry * np.sin(a), z])
            t2 = np.tile([0.0, 0.0, 1.0], (len(a), 1))
            s = np.full(len(a), WIDTH_FACTOR * min(spacing, perimeter / na))
            ao = 1.0 - 0.3 * np.exp(-z / 0.15)
            out.append(
                _Samples(
                    pos,
                    frame_quats(np.cross(t2, n), t2, n),
                    n,
                    s,
                    s,
                    np.column_stack([a * rx, z]),
                    np.full(len(a), _codes([_instance_material(p)])[0]),
                    ao,
                )
            )
            top = _faces(
                np.array([[cx - rx, cy - ry, p.z1]]), np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]),
                np.array([2 * rx]), np.array([2 * ry]), np.array([_instance_material(p)], object), np.array([False]), spacing, rng,
            )  # fmt: skip
            inside = ((top.pos[:, 0] - cx) / rx) ** 2 + ((top.pos[:, 1] - cy) / ry) ** 2 <= 1
            out.append(_Samples(*(getattr(top, f)[inside] for f in _Samples.__dataclass_fields__)))
        elif p.kind == "ellipsoid":
            rz = (p.z1 - p.z0) / 2
            area = 4 * math.pi * ((rx * ry) ** 1.6 + (rx * rz) ** 1.6 + (ry * rz) ** 1.6) ** (1 / 1.6) / 3 ** (1 / 1.6)
            count = max(32, int(area / spacing**2))
            k = np.arange(count) + 0.5
            polar = np.arccos(1 - 2 * k / count)
            azimuth = math.pi * (1 + 5**0.5) * k
            unit = np.column_stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)])
            unit *= 1.0 + 0.12 * rng.uniform(-1, 1, (count, 1))  # leafy, not a smooth ball
            pos = np.column_stack([cx + rx * unit[:, 0], cy + ry * unit[:, 1], p.z0 + rz + rz * unit[:, 2]])
            n = unit / np.linalg.norm(unit, axis=1, keepdims=True)
            helper = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0.0, 0, 1]]), np.array([[1.0, 0, 0]]))
            t1 = np.cross(helper, n)
            t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
            s = np.full(count, WIDTH_FACTOR * spacing)
            ao = 0.75 + 0.25 * (n[:, 2] + 1) / 2
            quat = frame_quats(t1, np.cross(n, t1), n)
            out.append(
                _Samples(pos, quat, n, s, s, pos[:, :2] * 7.0, np.full(count, _codes([_instance_material(p)])[0]), ao)
            )
    return _Samples.concat(out)


def _walls(d: Dressing, spacing: float, rng) -> _Samples:
    """Vertical faces along every wall polygon edge whose front is floor (free or under an object)."""
    origins, eus, lens, reach = [], [], [], []
    for poly in d.walls:
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords)
            a, b = pts[:-1], pts[1:]
            e = b - a
            keep = np.linalg.norm(e, axis=1) > 1e-6
            a, e = a[keep], e[keep]
            # a right turn (the room on the right) is an inside corner of the room: both faces run on
            # past it by half a spacing, behind the other face, so that where the two sheets' last
            # jittered columns leave the corner line thinly covered the other's run-on fills it from
            # behind (no dark seam down the corner); an outside corner gets no run-on (no fin)
            turn = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
            inner = turn < -1e-9
            origins.append(a)
            eus.append(e)
            lens.append(np.linalg.norm(e, axis=1))
            reach.append(np.column_stack([np.roll(inner, 1), inner]) * (0.5 * spacing))
    if not origins:
        return _Samples.concat([])
    a, e, length, reach = np.vstack(origins), np.vstack(eus), np.concatenate(lens), np.vstack(reach)
    # the ring runs with the wall on its left, so the room is on its right: the face frame (eu, ez) with
    # eu along the edge has its normal eu × ez pointing right, into the room
    eu = np.column_stack([e / length[:, None], np.zeros(len(e))])
    origin = np.column_stack([a, np.zeros(len(a))]) - eu * reach[:, :1]
    ez = np.tile([0.0, 0.0, 1.0], (len(a), 1))
    h = np.full(len(a), d.ceiling_height)
    run = length + reach.sum(axis=1)
    s = _faces(
        origin,
        eu,
        ez,
        run,
        h,
        np.full(len(a), d.wall_material, object),
        np.zeros(len(a), bool),
        spacing,
        rng,
        sharp=False,
    )
    # which face each sample is on, and where along its edge (run-on samples lie outside [0, length])
    face = np.repeat(np.arange(len(a)), np.prod(_face_grid(run, h, spacing), axis=0))
    along = np.einsum("ij,ij->i", s.pos - np.column_stack([a, np.zeros(len(a))])[face], eu[face])
    grid = d.grid
    # a run-on sample stands behind the next face: whether a room is in front is asked at the corner
    at = np.column_stack([a, np.zeros(len(a))])[face] + eu[face] * np.clip(along, 0.0, length[face])[:, None]
    front = np.where(((along < 0) | (along > length[face]))[:, None], at, s.pos)[:, :2]
    front = front + s.n[:, :2] * (0.5 * grid.resolution + 0.01)
    rc = grid.to_cell(front)
    rows, cols = grid.shape
    inside = (rc[:, 0] >= 0) & (rc[:, 0] < rows) & (rc[:, 1] >= 0) & (rc[:, 1] < cols)
    ok = np.zeros(len(rc), bool)
    ok[inside] = d.floor_mask[rc[inside, 0], rc[inside, 1]]
    s = _Samples(*(getattr(s, f)[ok] for f in _Samples.__dataclass_fields__))
    # ambient occlusion: near the floor and the ceiling, and in inside corners (little room in front)
    room = clearance_field(~d.wall_mask, grid.resolution)
    probe = grid.to_cell(s.pos[:, :2] + s.n[:, :2] * 0.35)
    probe = np.clip(probe, 0, np.array(grid.shape) - 1)
    corner = np.clip((0.35 - room[probe[:, 0], probe[:, 1]]) / 0.35, 0.0, 1.0)
    z = s.pos[:, 2]
    s.ao = (1 - 0.28 * np.exp(-z / 0.25)) * (1 - 0.18 * np.exp(-(d.ceiling_height - z) / 0.2)) * (1 - 0.3 * corner)
    return s


def _floor_and_ceiling(d: Dressing, spacing: float, rng) -> _Samples:
    grid = d.grid
    x0, y0 = grid.origin
    width, height = grid.shape[1] * grid.resolution, grid.shape[0] * grid.resolution
    gx, gy = np.meshgrid(np.arange(spacing / 2, width, spacing), np.arange(spacing / 2, height, spacing))
    xy = np.column_stack([gx.ravel() + x0, gy.ravel() + y0])
    xy += rng.uniform(-JITTER, JITTER, xy.shape) * spacing
    rc = np.clip(grid.to_cell(xy), 0, np.array(grid.shape) - 1)
    keep = d.floor_mask[rc[:, 0], rc[:, 1]]
    xy, rc = xy[keep], rc[keep]
    n = len(xy)
    near_obstacle = clearance_field(grid.free, grid.resolution)[rc[:, 0], rc[:, 1]]
    near_wall = clearance_field(~d.wall_mask, grid.resolution)[rc[:, 0], rc[:, 1]]
    up, down = np.tile([0.0, 0, 1.0], (n, 1)), np.tile([0.0, 0, -1.0], (n, 1))
    x, y, z = np.eye(3)
    up_quat, down_quat = frame_quats(np.array([x, y]), np.array([y, x]), np.array([z, -z]))
    s = np.full(n, WIDTH_FACTOR * spacing)
    names, index = d.floor_materials_at(xy)
    floor = _Samples(
        np.column_stack([xy, np.zeros(n)]), np.tile(up_quat, (n, 1)), up, s, s, xy, _codes(names)[index],
        1 - 0.35 * np.exp(-near_obstacle / 0.2),
    )  # fmt: skip
    ceiling = _Samples(
        np.column_stack([xy, np.full(n, d.ceiling_height)]), np.tile(down_quat, (n, 1)), down, s, s, xy,
        np.full(n, _codes(["ceiling"])[0]), 1 - 0.25 * np.exp(-near_wall / 0.3),
    )  # fmt: skip
    return _Samples.concat([floor, ceiling])


def frame_quats(t1: np.ndarray, t2: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(N, 4) wxyz rotations whose matrix has columns t1, t2, n (orthonormal right-handed frames (N, 3) each).

    Shepperd's method evaluated for all four branches at once and selected per row by the largest of
    (trace, m00, m11, m22): exact for rotation matrices, 180° turns included (every ceiling surfel is
    one), and several times faster than a row-by-row extraction at this size.
    """
    m00, m10, m20 = t1.T
    m01, m11, m21 = t2.T
    m02, m12, m22 = n.T
    trace = m00 + m11 + m22
    branch = np.argmax(np.column_stack([trace, m00, m11, m22]), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.sqrt(
            np.maximum(1e-300, 1.0 + np.choose(branch, [trace, m00 - m11 - m22, m11 - m00 - m22, m22 - m00 - m11]))
        )
        half, inv = 0.5 * r, 0.5 / r
        candidates = [
            np.column_stack([half, (m21 - m12) * inv, (m02 - m20) * inv, (m10 - m01) * inv]),
            np.column_stack([(m21 - m12) * inv, half, (m01 + m10) * inv, (m02 + m20) * inv]),
            np.column_stack([(m02 - m20) * inv, (m01 + m10) * inv, half, (m12 + m21) * inv]),
            np.column_stack([(m10 - m01) * inv, (m02 + m20) * inv, (m12 + m21) * inv, half]),
        ]
    q = np.choose(branch[:, None], candidates)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0, -q, q)


def _albedo(s: _Samples, seed: int, flat: bool = False) -> np.ndarray:
    """Display-space albedo of each sample: its material's texture (``flat``: the material's base colour)."""
    from song.datasets.scenes.materials import material_of

    colour = np.zeros((len(s.pos), 3))
    order = np.argsort(s.material, kind="stable")
    codes = np.unique(s.material)
    bounds = np.searchsorted(s.material[order], np.concatenate([codes, [np.iinfo(np.int32).max]]))
    for k, code in enumerate(codes):
        rows = order[bounds[k] : bounds[k + 1]]
        name = _MATERIAL_NAMES[code]
        if flat:  # the material's own base colour, as the reference renders read it from the USD proxy
            colour[rows] = material_of(name.split("~")[0]).base
        else:
            colour[rows] = texture(name, s.uv[rows, 0], s.uv[rows, 1], seed + zlib.crc32(name.encode()) % 65521)
    return colour


def _flat_shading(s: _Samples, albedo: np.ndarray) -> np.ndarray:
    """The unlit look: a soft light from above and the procedural occlusion, in display space."""
    shade = AMBIENT + DIFFUSE * np.maximum(s.n @ LIGHT, 0.0)
    return np.clip(albedo * (shade * s.ao)[:, None], 0.0, 1.0)


def synthesize_gaussians(
    dressing: Dressing, spacing: float = SPACING_M, lighting: tuple | None = None, flat_materials: bool = False
) -> tuple[GaussianCloud, Bake | None]:
    """Surfels over every visible surface of ``dressing`` (see the module docstring), seeded by its seed.

    ``lighting`` = ``(rig, triangles)`` bakes the rig's light with the proxy triangles (T, 3, 3) as
    occluders (:func:`song.datasets.scenes.lighting.bake`); None keeps the unlit look.
    ``flat_materials`` colours every surface with its material's base colour (no texture), as the
    Cycles comparison needs. Returns the cloud and the bake (None when unlit).
    """
    from song.datasets.scenes.lighting import bake as bake_light
    from song.datasets.scenes.lighting import column_bounds
    from song.datasets.scenes.materials import srgb_to_linear

    rng = derive_rng(dressing.seed, "splat", dressing.grid.shape, dressing.venue)
    boxes = [p for p in dressing.parts if p.kind == "box"]
    rounds = [p for p in dressing.parts if p.kind != "box"]
    samples = _Samples.concat(
        [
            _floor_and_ceiling(dressing, spacing, rng),
            _walls(dressing, spacing, rng),
            _faces(*_box_faces(boxes), spacing, rng),
            _round_parts(rounds, spacing, rng),
        ]
    )
    albedo = _albedo(samples, dressing.seed, flat_materials)
    baked = None
    if lighting is None:
        colour = _flat_shading(samples, albedo)
    else:
        rig, triangles = lighting
        floor = (dressing.grid, dressing.floor_mask)
        baked = bake_light(samples.pos, samples.n, srgb_to_linear(albedo), samples.ao, triangles, rig, floor)
        colour = baked.colour
    quats = samples.quat
    thin = THIN_FACTOR * np.minimum(samples.s1, samples.s2) / WIDTH_FACTOR
    scales = np.column_stack([samples.s1, samples.s2, thin])
    cell = np.floor(samples.pos / SORT_CELL_M).astype(np.int64)
    low, high = column_bounds(cell)
    cell -= low
    span = high - low + 1
    key = (cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")  # x-major cells; generation order within a cell
    cloud = GaussianCloud(
        means=samples.pos[order].astype(np.float32),
        quats=quats[order].astype(np.float32),
        log_scales=np.log(scales[order]).astype(np.float32),
        opacity_logits=np.full(len(order), OPACITY_LOGIT, np.float32),
        sh_dc=((colour[order] - 0.5) / SH_C0).astype(np.float32),
    )
    return cloud, baked


@dataclass(frozen=True)
class DressResult:
    """What :func:`dress_package` wrote: the Gaussian count and the file sizes."""

    scene_id: str
    gaussians: int
    ply_mb: float
    usd_kb: float


def write_proxy(root: str | Path, hints: DressingHints) -> None:
    """Write only the package's USD proxy (with ``hints`` in its metadata) from its dressing."""
    from song.datasets.scenes.package import USD_PROXY, load_scene_package
    from song.datasets.scenes.proxy import dressing_meshes, room_meshes
    from song.datasets.scenes.usd import write_usd_proxy

    package = load_scene_package(root, min_free_area_m2=0.0)
    dressing = build_dressing(package.semantic_map, package.occupancy, hints)
    solids, surfaces = dressing_meshes(dressing, {o.id: o.category for o in package.semantic_map.objects})
    rooms = room_meshes(package.semantic_map)
    write_usd_proxy(Path(root) / USD_PROXY, solids, surfaces, hints.to_json(), rooms)


def _check_splat_count(root: Path, package, spacing: float) -> None:
    """Refuse a spacing that would make more surfels than ``max_splats`` (estimated before any is made).

    The floor and the ceiling alone take (floor area / spacing²) surfels each: a lower bound.
    """
    from song.datasets.limits import limits, over
    from song.errors import SceneError

    grid = package.occupancy
    floor_m2 = float(np.count_nonzero(grid.cells != 0)) * grid.resolution**2
    estimate = int(2 * floor_m2 / spacing**2)
    if estimate > limits().max_splats:
        raise over(root, "spacing", f"{spacing} m spacing makes at least", estimate, "max_splats", SceneError)


def proxy_triangles(solids, surfaces) -> np.ndarray:
    """(T, 3, 3) triangles of the proxy meshes (the baker's occluders)."""
    meshes = [*solids, *surfaces]
    if not meshes:
        return np.zeros((0, 3, 3))
    return np.concatenate([np.asarray(m.vertices, dtype=np.float64)[np.asarray(m.faces)] for m in meshes])


def dress_package(
    root: str | Path,
    hints: DressingHints | None = None,
    spacing: float = SPACING_M,
    seed: int | None = None,
    light: bool = True,
) -> DressResult:
    """Write a package's ``3dgs_compressed.ply`` and ``scene_flat.usda`` from its semantic map and occupancy.

    ``hints`` default to the ones stored in the package's USD proxy (none when it has no proxy), so a
    package made by the generator or the ProcTHOR importer is rebuilt exactly; ``seed`` replaces theirs.
    ``light`` bakes the package's ``lights.json`` into the Gaussians (placing and writing the lights
    first when the package has none; an existing file is never changed); the probe grid and the
    exposure go into the USD proxy's metadata and the lights into it as ``UsdLux`` prims.
    """
    from song.datasets.scenes.lights import LIGHTS_FILE, place_lights, read_lights, write_lights
    from song.datasets.scenes.package import GAUSSIANS, USD_PROXY, load_scene_package
    from song.datasets.scenes.ply import write_compressed_ply
    from song.datasets.scenes.proxy import dressing_meshes, room_meshes
    from song.datasets.scenes.usd import read_usd_dressing, write_usd_proxy

    root = Path(root)
    package = load_scene_package(root, min_free_area_m2=0.0)
    if hints is None and (root / USD_PROXY).is_file():
        text = read_usd_dressing(root / USD_PROXY)
        hints = DressingHints.from_json(text) if text else None
    hints = hints or DressingHints()
    if seed is not None:
        hints = dataclasses.replace(hints, seed=seed)
    _check_splat_count(root, package, spacing)
    dressing = build_dressing(package.semantic_map, package.occupancy, hints)
    solids, surfaces = dressing_meshes(dressing, {o.id: o.category for o in package.semantic_map.objects})
    rig, lighting = None, None
    if light:
        lights_path = root / LIGHTS_FILE
        rig = read_lights(lights_path) if lights_path.is_file() else place_lights(dressing, package.semantic_map, hints)
        lighting = (rig, proxy_triangles(solids, surfaces))
    cloud, baked = synthesize_gaussians(dressing, spacing, lighting)
    write_compressed_ply(root / GAUSSIANS, cloud, viewer_frame=True)  # upright in SuperSplat and co.
    if rig is not None and not (root / LIGHTS_FILE).is_file():
        write_lights(root / LIGHTS_FILE, rig)
    write_usd_proxy(
        root / USD_PROXY, solids, surfaces, hints.to_json(), room_meshes(package.semantic_map),
        lights=rig.lights if rig else (), lighting_json=baked.probes.to_json() if baked and baked.probes else None,
    )  # fmt: skip
    return DressResult(
        package.scene_id, len(cloud), (root / GAUSSIANS).stat().st_size / 1e6, (root / USD_PROXY).stat().st_size / 1e3
    )
