"""The local-avoidance seam of the crowd simulation.

DetourCrowd keeps obstacle avoidance in its own module and picks it by parameter; so does this crowd,
with ``crowd.avoidance``.

The simulation hands a model the pedestrians it must steer this frame -- positions, current and
preferred velocities, body radii, speed limits -- and gets their new velocities back; walls come from
the navmesh the model was built for. Adding a model is one class here plus one entry in
:data:`AVOIDANCE_MODELS`.

- ``orca``: RVO2's optimal reciprocal collision avoidance (:mod:`song.pipeline.crowd.orca`) against
  the other pedestrians and the navmesh's walls (grown back by the body radius).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from song.config import CrowdConfig
from song.geometry.navmesh import Navmesh, obstacle_rings
from song.pipeline.crowd.orca import ObstacleSet, OrcaParams, build_obstacles, orca_step

WALL_MARGIN_M = 0.005  # ORCA walls lie this much beyond the agent radius from the mesh


class LocalAvoidance(Protocol):
    """A local-avoidance model for one scene (built once per simulation)."""

    name: str

    def velocities(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        preferred: np.ndarray,
        radii: np.ndarray,
        max_speeds: np.ndarray,
    ) -> np.ndarray:
        """New (N, 2) velocities, m/s.

        Args:
            positions: (N, 2) m.
            velocities: (N, 2) current velocities, m/s.
            preferred: (N, 2) preferred velocities, m/s.
            radii: (N,) body radii, m.
            max_speeds: (N,) speed limits, m/s (0 for a standing pedestrian).
        """
        ...


def orca_walls(mesh: Navmesh) -> ObstacleSet | None:
    """ORCA walls: the mesh grown back by its agent radius (+ a 5 mm margin), in RVO2 vertex order."""
    rings = obstacle_rings(mesh, mesh.params.agent_radius + WALL_MARGIN_M)
    return build_obstacles(rings) if rings else None


class OrcaAvoidance:
    """RVO2's ORCA with the crowd's neighbour distance, neighbour cap and time horizons."""

    name = "orca"

    def __init__(self, mesh: Navmesh, cfg: CrowdConfig) -> None:
        self.params = OrcaParams(
            1.0 / cfg.fps, cfg.neighbor_dist_m, cfg.max_neighbors, cfg.time_horizon_s, cfg.time_horizon_obst_s
        )
        self.walls = orca_walls(mesh)

    @property
    def neighbor_dist(self) -> float:
        """Agents farther apart than this cannot affect each other's answer, m."""
        return self.params.neighbor_dist

    def velocities(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        preferred: np.ndarray,
        radii: np.ndarray,
        max_speeds: np.ndarray,
    ) -> np.ndarray:
        """ORCA's new velocities (see :func:`song.pipeline.crowd.orca.orca_step`)."""
        return orca_step(positions, velocities, preferred, radii, max_speeds, self.walls, self.params)


AVOIDANCE_MODELS: dict[str, Callable[[Navmesh, CrowdConfig], LocalAvoidance]] = {"orca": OrcaAvoidance}


def make_avoidance(mesh: Navmesh, cfg: CrowdConfig) -> LocalAvoidance:
    """The model named by ``cfg.avoidance`` for ``mesh``."""
    return AVOIDANCE_MODELS[cfg.avoidance](mesh, cfg)
