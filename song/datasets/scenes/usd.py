"""USD collision proxy ``scene_flat.usda`` (DESIGN §4.3): Z-up, metres, /World/collision meshes.

CONTRACT (other modules rely on these names and signatures):
    ProxyBox                 dataclass below
    write_usd_proxy(path, boxes: list[ProxyBox]) -> None
    read_usd_proxy(path) -> list[ProxyMesh]   (name, vertices (V,3) float64, faces (F,3) int)
usd-core (``pxr``) is imported lazily; missing → MissingDependencyError with the install hint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
