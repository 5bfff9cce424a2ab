"""A navmesh as plain arrays (``navmesh.npz``), with its build parameters, and back."""

from __future__ import annotations

import numpy as np

from song.geometry.navmesh.mesh import Navmesh, NavmeshParams


def navmesh_arrays(mesh: Navmesh) -> dict[str, np.ndarray]:
    """The mesh as plain arrays (for ``np.savez``); :func:`navmesh_from_arrays` reads them back."""
    return {
        "params": mesh.params.to_array(),
        "vertices": mesh.vertices,
        "triangles": mesh.triangles,
        "neighbours": mesh.neighbours,
        "segments": mesh.segments,
        "seg_triangle": mesh.seg_triangle,
        "component": mesh.component,
        "reflex": mesh.reflex,
        "vis_edges": mesh.vis_edges,
    }


def navmesh_from_arrays(arrays) -> Navmesh:
    """Inverse of :func:`navmesh_arrays` (``arrays``: a mapping such as an open ``np.load``)."""
    names = ("vertices", "triangles", "neighbours", "segments", "seg_triangle", "component", "reflex", "vis_edges")
    return Navmesh(**{k: np.asarray(arrays[k]) for k in names}, params=NavmeshParams.from_array(arrays["params"]))
