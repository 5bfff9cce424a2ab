"""The navmesh as data: its arrays, its build parameters and the flat arrays the compiled queries read."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from song.geometry import _navmesh_kernel as _k
from song.geometry.navmesh.query import NavmeshQueries, _cross

NAVMESH_FORMAT = 1
BUCKET_M = 0.5  # cell size of the spatial hash used for wall and triangle look-ups


@dataclass(frozen=True)
class NavmeshParams:
    """Build parameters, stored with the mesh.

    Attributes:
        agent_radius: radius the free space was eroded by, m.
        resolution: grid cell size, m.
        origin: (x_min, y_min) of the grid, m.
        shape: (rows, cols) of the grid.
        contour_error: simplification error ε, m (the boundary lies within ε inside the legal cells).
    """

    agent_radius: float
    resolution: float
    origin: tuple[float, float]
    shape: tuple[int, int]
    contour_error: float

    def to_array(self) -> np.ndarray:
        """The parameters as a float64 array (stored in navmesh.npz)."""
        return np.array(
            [NAVMESH_FORMAT, self.agent_radius, self.resolution, *self.origin, *self.shape, self.contour_error],
            dtype=np.float64,
        )

    @classmethod
    def from_array(cls, a: np.ndarray) -> NavmeshParams:
        """Inverse of :meth:`to_array`; refuses another navmesh format."""
        if int(a[0]) != NAVMESH_FORMAT:
            raise ValueError(f"navmesh format {int(a[0])} is not {NAVMESH_FORMAT}")
        return cls(float(a[1]), float(a[2]), (float(a[3]), float(a[4])), (int(a[5]), int(a[6])), float(a[7]))


def _ring_links(n_vertices: int, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(prev, next)`` (V,) int64: each boundary vertex's neighbours along its ring (-1 off the boundary)."""
    prev = np.full(n_vertices, -1, dtype=np.int64)
    nxt = np.full(n_vertices, -1, dtype=np.int64)
    nxt[segments[:, 0]] = segments[:, 1]
    prev[segments[:, 1]] = segments[:, 0]
    return prev, nxt


@dataclass
class Navmesh(NavmeshQueries):
    """A triangulated navigation mesh (plain data; see :func:`build_navmesh`).

    Attributes:
        vertices: (V, 2) float64, m.
        triangles: (T, 3) int64 vertex ids, counter-clockwise.
        neighbours: (T, 3) int64 triangle across edge (t[k], t[k+1]), -1 on the boundary.
        segments: (S, 2) int64 boundary edges (vertex ids), the mesh on their left.
        seg_triangle: (S,) int64 the triangle each boundary edge belongs to.
        component: (T,) int64 connected part of each triangle.
        reflex: (R,) int64 reflex boundary vertices.
        vis_edges: (E, 2) int64 bitangent visible pairs of ``reflex`` positions (i < j).
        params: the build parameters.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    neighbours: np.ndarray
    segments: np.ndarray
    seg_triangle: np.ndarray
    component: np.ndarray
    reflex: np.ndarray
    vis_edges: np.ndarray
    params: NavmeshParams
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # ---- derived arrays -------------------------------------------------------------------------
    @property
    def seg_a(self) -> np.ndarray:
        """(S, 2) start points of the boundary segments, m."""
        return self.vertices[self.segments[:, 0]]

    @property
    def seg_b(self) -> np.ndarray:
        """(S, 2) end points of the boundary segments, m."""
        return self.vertices[self.segments[:, 1]]

    def _geometry(self) -> dict:
        """Flat arrays of the mesh's shape alone, built once: its vertices, triangles, walls and spatial hashes.

        ``verts, tris, va, vb`` (the walls' vertex ids), ``reflex, prev, next`` (each boundary vertex's
        neighbours along its ring) and the hashes ``grid, tstart, titems, sstart, sitems``. They depend
        only on the vertices, triangles and boundary segments, so :func:`navmesh_from_polygons` queries
        them (:meth:`locate`, the visibility graph) before it has filled in the fields that
        :meth:`_kernel` adds (the boundary edges' triangles, the visibility graph).
        """
        if "geometry" not in self._cache:
            verts = np.ascontiguousarray(self.vertices, dtype=np.float64)
            lo = verts.min(axis=0) - BUCKET_M if len(verts) else np.zeros(2)
            hi = verts.max(axis=0) + BUCKET_M if len(verts) else np.ones(2)
            n = np.maximum(np.ceil((hi - lo) / BUCKET_M).astype(np.int64), 1)
            tri = verts[self.triangles].reshape(-1, 3, 2)
            a, b = self.seg_a.reshape(-1, 2), self.seg_b.reshape(-1, 2)
            margin = 1e-4  # beyond rounding: a ray meets every wall it touches in the cells it walks
            tstart, titems = _k.hash_boxes(tri.min(axis=1) - margin, tri.max(axis=1) + margin, lo, n, BUCKET_M)
            sstart, sitems = _k.hash_boxes(np.minimum(a, b) - margin, np.maximum(a, b) + margin, lo, n, BUCKET_M)
            prev, nxt = _ring_links(len(verts), self.segments)
            self._cache["geometry"] = {
                "verts": verts,
                "tris": np.ascontiguousarray(self.triangles, dtype=np.int64),
                "va": np.ascontiguousarray(self.segments[:, 0], dtype=np.int64),
                "vb": np.ascontiguousarray(self.segments[:, 1], dtype=np.int64),
                "reflex": np.ascontiguousarray(self.reflex, dtype=np.int64),
                "prev": prev,
                "next": nxt,
                "grid": np.array([lo[0], lo[1], BUCKET_M, n[0], n[1]], dtype=np.float64),
                "tstart": tstart,
                "titems": titems,
                "sstart": sstart,
                "sitems": sitems,
            }
        return self._cache["geometry"]

    def _kernel(self) -> dict:
        """:meth:`_geometry`'s arrays plus the boundary edges' triangles and the visibility graph, built once.

        The flat arrays the compiled queries (:mod:`song.geometry._navmesh_kernel`) take.
        """
        if "kernel" not in self._cache:
            g = self._geometry()
            verts, reflex = g["verts"], g["reflex"]
            e = self.vis_edges.reshape(-1, 2)
            length = np.hypot(*(verts[reflex[e[:, 0]]] - verts[reflex[e[:, 1]]]).T)
            adj = sparse.csr_matrix(
                (np.r_[length, length], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                shape=(len(reflex),) * 2,
            )
            adj.sort_indices()
            self._cache["kernel"] = {
                **g,
                "seg_tri": np.ascontiguousarray(self.seg_triangle, dtype=np.int64),
                "seg_comp": np.ascontiguousarray(self.component[self.seg_triangle], dtype=np.int64),
                "vptr": adj.indptr.astype(np.int64),
                "vidx": adj.indices.astype(np.int64),
                "vlen": adj.data.astype(np.float64),
            }
            k = self._cache["kernel"]
            comp = np.ascontiguousarray(self.component, dtype=np.int64)
            names = ("verts", "tris", "seg_tri", "seg_comp", "va", "vb", "reflex", "prev", "next")
            tail = ("grid", "tstart", "titems", "sstart", "sitems", "vptr", "vidx", "vlen")
            self._cache["args"] = (*(k[n] for n in names), comp, *(k[n] for n in tail))
        return self._cache["kernel"]

    def _kernel_args(self) -> tuple:
        """The kernel arrays as the one tuple :func:`song.geometry._navmesh_kernel.find_path` takes."""
        self._kernel()
        return self._cache["args"]

    def move_args(self) -> tuple:
        """The kernel arrays compiled moves on the mesh take (``settle_moves`` of the crowd simulation).

        ``(va, vb, verts, tris, seg_tri, wall grid, wall start, wall items, triangle grid, triangle start,
        triangle items)``: enough for :meth:`constrain_moves`, :meth:`segment_clear` and :meth:`contains`.
        """
        if "move_args" not in self._cache:
            k = self._kernel()
            names = ("va", "vb", "verts", "tris", "seg_tri", "grid", "sstart", "sitems", "grid", "tstart", "titems")
            self._cache["move_args"] = tuple(k[n] for n in names)
        return self._cache["move_args"]

    @property
    def area(self) -> float:
        """Mesh area, m²."""
        t = self.vertices[self.triangles]
        return float(0.5 * _cross(*(t[:, 1] - t[:, 0]).T, *(t[:, 2] - t[:, 0]).T).sum())
