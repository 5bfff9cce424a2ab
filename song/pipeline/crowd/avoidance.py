"""The local-avoidance seam of the crowd simulation.

DetourCrowd keeps obstacle avoidance in its own module and picks it by parameter; so does this crowd,
with ``crowd.avoidance``.

The simulation hands a model the pedestrians it must steer this frame -- positions, current and
preferred velocities, body radii, speed limits -- and gets their new velocities back; walls come from
the navmesh the model was built for. A model is a class ``Model(mesh, cfg)`` with the
:class:`LocalAvoidance` methods, registered as an ``avoidance`` plugin (:mod:`song.plugins`) and named
by ``crowd.avoidance``. Whatever the model, the simulation afterwards keeps every move on the mesh
and resolves body overlaps, so contact (centres closer than 2 × body radius) never happens.

Body and personal space are separate: the body radius (``crowd.agent_radius_m``) is what touches; in
open space people also keep ``crowd.comfort_distance_m`` between centres when they pass, and
``crowd.wall_comfort_m`` more than their body from walls, and give that up gracefully where a passage
is too narrow for it, or the crowd too dense.

- ``orca`` (default): preferred velocities bent aside early from people who would pass closer than the
  comfort distance (:func:`anticipate`), then RVO2's optimal reciprocal collision avoidance
  (:mod:`song.pipeline.crowd.orca`) with each walker's personal space as its radius
  (:func:`personal_radii`: half the comfort distance where the passage is wide enough, shrinking to
  the body in a narrow one, when it is about to touch someone's, and as the walker is held up in a
  jam), the body radius for people standing, the body radius plus the wall comfort (within the room
  it has) against walls, and the whole avoidance -- not RVO2's half -- against someone standing
  still. ORCA keeps collisions of personal space out for ``crowd.time_horizon_s`` (2 s) and keeps
  the walker's pace where the half-planes allow it (:attr:`song.pipeline.crowd.orca.OrcaParams.
  keep_pace`); passes are anticipated ``crowd.anticipation_s`` (4 s) ahead.
- ``social_force``: Helbing & Molnár's social-force model (Phys. Rev. E 51, 4282, 1995) with the
  pedestrian interaction of Moussaïd et al. (Proc. R. Soc. B 276, 2755, 2009; the anisotropic,
  velocity-dependent form fitted to controlled experiments) and an exponential wall repulsion:
  ``dv/dt = (v₀ e − v)/τ + Σⱼ f_ij + f_wall`` with the constants below.
"""

from __future__ import annotations

from typing import Protocol

import numba
import numpy as np

from song import plugins
from song.config import CrowdConfig
from song.geometry.navmesh import Navmesh, obstacle_rings
from song.pipeline.crowd._orca_kernel import step_kernel
from song.pipeline.crowd.orca import ObstacleSet, OrcaParams, build_obstacles, kernel_tail

WALL_MARGIN_M = 0.005  # ORCA walls lie this much beyond the agent radius from the mesh
ROOM_MARGIN_M = 0.01  # the wall comfort never reaches closer than this to a wall
ANTICIPATION_GAIN = 4.0  # sideways share of the heading per unit of predicted comfort shortfall (open space)
ANTICIPATION_MARGIN_M = 0.1  # the bend aims this far beyond the comfort distance (it fades to nothing at its aim)
HALF_WIDTH_STEP_M = 0.05  # the passage half-width is resolved to this
PERSONAL_MARGIN_M = 0.005  # a personal radius stays this far from touching anyone's (ORCA's collision branch)
HELD_UP_S = 0.5  # a walker with no progress for this long starts giving up personal space (all it gives by twice that)
HELD_UP_GIVE = 0.6  # the share of its personal space (beyond the body) that a held-up walker gives up

# social force (Moussaïd et al. 2009, Table 1; relaxation time and walls as in pedsim_ros' defaults)
SF_RELAXATION_S = 0.5  # τ: time to reach the preferred velocity
SF_STRENGTH = 4.5  # A, m/s²
SF_LAMBDA = 2.0  # weight of the relative velocity in the interaction direction
SF_GAMMA = 0.35  # B = γ ‖D‖, the interaction range
SF_N, SF_N_PRIME = 2.0, 3.0  # angular sharpness of the deceleration (n′) and turning (n) terms
SF_WALL_STRENGTH = 10.0  # m/s²
SF_WALL_RANGE_M = 0.2  # exponential decay of the wall repulsion beyond the body, m
SF_RANGE_M = 5.0  # people farther apart than this do not interact, m


class LocalAvoidance(Protocol):
    """A local-avoidance model for one scene (built once per simulation)."""

    name: str

    @property
    def neighbor_dist(self) -> float:
        """Agents farther apart than this cannot affect each other's answer, m."""
        ...

    def velocities(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        preferred: np.ndarray,
        radii: np.ndarray,
        max_speeds: np.ndarray,
        held_up: np.ndarray,
    ) -> np.ndarray:
        """New (N, 2) velocities, m/s.

        Args:
            positions: (N, 2) m.
            velocities: (N, 2) current velocities, m/s.
            preferred: (N, 2) preferred velocities, m/s.
            radii: (N,) body radii, m.
            max_speeds: (N,) speed limits, m/s (0 for a standing pedestrian).
            held_up: (N,) seconds since each walker last got closer to its goal (0 for those standing).
        """
        ...


class WallDistance:
    """Distance from a point to the nearest wall (the mesh grown back by its agent radius), m.

    The mesh's triangles are rasterised on its own grid once and a distance transform gives each legal
    cell its distance to the mesh boundary; adding the agent radius gives the distance to the wall.
    One value per cell: within a cell the answer can exceed the true distance. On the sample scenes,
    over random mesh points within 0.35 m of the boundary, it exceeds it by up to 8–10 cm, and by more
    than 5 mm at 36–52 % of them. So the wall comfort's cap (``wall − ROOM_MARGIN_M``) can hold a
    walker a few centimetres off a wall. An exact query was tried and not kept (docs/crowd.md, walls).
    """

    def __init__(self, mesh: Navmesh) -> None:
        import cv2
        from scipy import ndimage

        p = mesh.params
        rows, cols = p.shape
        legal = np.zeros((rows, cols), np.uint8)
        corners = mesh.vertices[mesh.triangles]  # (T, 3, 2) world m
        px = np.stack(
            [(corners[..., 0] - p.origin[0]) / p.resolution, rows - (corners[..., 1] - p.origin[1]) / p.resolution], -1
        )
        cv2.fillPoly(legal, [np.round(t * 8).astype(np.int32) for t in px], 1, lineType=cv2.LINE_8, shift=3)
        # a cell centre's distance to the nearest outside cell overstates the distance to the boundary by up
        # to a cell: take one cell off (LINE_8 also marks cells the boundary only touches; see the class doc)
        self.field = np.maximum(ndimage.distance_transform_edt(legal) - 1.0, 0.0) * p.resolution + p.agent_radius
        self.params = p
        self._half_width: dict[float, np.ndarray] = {}

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        col = np.minimum(np.maximum(((xy[:, 0] - p.origin[0]) / p.resolution).astype(np.int64), 0), p.shape[1] - 1)
        row = np.minimum(np.maximum((p.shape[0] - (xy[:, 1] - p.origin[1]) / p.resolution).astype(np.int64), 0),
                         p.shape[0] - 1)  # fmt: skip
        return row, col

    def at(self, xy: np.ndarray) -> np.ndarray:
        """(N,) distance to the nearest wall at points (N, 2), m (the agent radius off the mesh)."""
        return self.field[self._cells(xy)]

    def thickness(self, upto: float) -> np.ndarray:
        """The grid of :meth:`half_width_at` (rows, cols), m."""
        if upto not in self._half_width:
            self._half_width[upto] = self._local_thickness(upto)
        return self._half_width[upto]

    def half_width_at(self, xy: np.ndarray, upto: float) -> np.ndarray:
        """(N,) half the width of the passage at points (N, 2), m, capped at ``upto``.

        The radius of the largest wall-free disc that holds the point ("local thickness", Hildebrand &
        Rüegsegger 1997): half the corridor's width in a corridor, however near a wall the point lies;
        the full ``upto`` in open space. Built once per cap from wall-free discs at 5 cm steps of radius.
        """
        return self.thickness(upto)[self._cells(xy)]

    def _local_thickness(self, upto: float) -> np.ndarray:
        import cv2

        p = self.params
        out = np.where(self.field > p.agent_radius, p.agent_radius, 0.0)
        for radius in np.arange(p.agent_radius + HALF_WIDTH_STEP_M, upto + 1e-9, HALF_WIDTH_STEP_M):
            k = max(int(round(radius / p.resolution)), 1)
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
            covered = cv2.dilate((self.field >= radius).astype(np.uint8), disc) > 0
            out[covered] = radius
        return out


@numba.njit(cache=True, nogil=True)
def _anticipate_kernel(
    positions, velocities, preferred, comfort_distance, horizon, reach, gain, margin
):  # pragma: no cover
    out = preferred.copy()
    n = len(positions)
    aim = comfort_distance + margin
    reach_sq = reach * reach
    for i in range(n):
        speed = np.hypot(preferred[i, 0], preferred[i, 1])
        if speed <= 1e-6:
            continue
        hx, hy = preferred[i, 0] / speed, preferred[i, 1] / speed
        sx, sy = -hy, hx
        push = 0.0
        for j in range(n):
            if j == i:
                continue
            px, py = positions[j, 0] - positions[i, 0], positions[j, 1] - positions[i, 1]
            if px * px + py * py >= reach_sq:
                continue
            vx, vy = velocities[j, 0] - preferred[i, 0], velocities[j, 1] - preferred[i, 1]
            vv = vx * vx + vy * vy
            t = min(max(-(px * vx + py * vy) / (vv if vv > 1e-9 else 1.0), 0.0), horizon)
            mx, my = px + vx * t, py + vy * t
            d = np.hypot(mx, my)
            away = 1.0 if mx * sx + my * sy < -1e-6 else -1.0
            push += away * max(aim - d, 0.0) / aim / (1.0 + t)
        bx, by = hx + gain[i] * push * sx, hy + gain[i] * push * sy
        norm = max(np.hypot(bx, by), 1e-9)
        out[i, 0], out[i, 1] = bx / norm * speed, by / norm * speed
    return out


def anticipate(
    positions: np.ndarray,
    velocities: np.ndarray,
    preferred: np.ndarray,
    comfort_distance: float,
    horizon: float,
    reach: float,
    room: np.ndarray | None = None,
) -> np.ndarray:
    """Preferred velocities bent aside, early, from people who would pass closer than the comfort distance.

    For each walker and each other pedestrian the closest approach is predicted with constant
    velocities (the walker at its preferred velocity) within ``horizon``; when it falls short of
    ``comfort_distance`` the walker's preferred direction gains a sideways component away from where
    the other will be, stronger the shorter the miss and the sooner it comes; people ``reach`` (the
    model's neighbour distance) or farther away are left out. The speed is unchanged. ``room`` (N,)
    in [0, 1] scales each walker's bend (default 1; :func:`swerve_room`: people swerve early only
    where there is room to).
    The crowd's hard constraints (ORCA at the personal radii of :func:`personal_radii`, walls, overlap
    resolution) still decide the velocity, so in a passage too narrow for comfort people simply pass at
    their body distance.

    Compiled (numba): a walker-by-pedestrian loop; the vectorised numpy form
    (:func:`song.pipeline.crowd._avoidance_reference.anticipate_reference`, its test twin) spent most
    of its time in dispatch at indoor crowd sizes.
    """
    if len(positions) < 2:
        return preferred
    return _anticipate_kernel(
        np.ascontiguousarray(positions, np.float64),
        np.ascontiguousarray(velocities, np.float64),
        np.ascontiguousarray(preferred, np.float64),
        float(comfort_distance),
        float(horizon),
        float(reach),
        ANTICIPATION_GAIN * (np.ones(len(positions)) if room is None else np.asarray(room, np.float64)),
        ANTICIPATION_MARGIN_M,
    )


@numba.njit(cache=True, nogil=True)
def swerve_room(half_width: float, radius: float, comfort_distance: float) -> float:  # pragma: no cover
    """How much of its early swerve a walker makes, 0–1.

    All of it where the passage's half-width leaves half the comfort distance beyond its body, none where
    the passage is only as wide as the body (in a narrow aisle a swerve only pushes people into the
    furniture; ORCA still keeps them apart).
    """
    return min(max((half_width - radius) / (0.5 * comfort_distance), 0.0), 1.0)


@numba.njit(cache=True, nogil=True)
def _personal_kernel(positions, radii, walking, half_width, comfort, margin):  # pragma: no cover
    out = radii.copy()
    n = len(positions)
    for i in range(n):
        if not walking[i]:
            continue
        best = min(comfort[i], half_width[i] - radii[i])
        for j in range(n):
            if j == i:
                continue
            d = np.hypot(positions[j, 0] - positions[i, 0], positions[j, 1] - positions[i, 1])
            fit = 0.5 * d if walking[j] else d - radii[j] - comfort[i]
            best = min(best, fit - margin)
        out[i] = max(best, radii[i])
    return out


def personal_radii(
    positions: np.ndarray,
    radii: np.ndarray,
    walking: np.ndarray,
    half_width: np.ndarray,
    comfort_radius: np.ndarray | float,
) -> np.ndarray:
    """ORCA radii ``(N,)`` of the walkers' personal space: ``comfort_radius`` where there is room.

    A walker's radius is at most the passage's half-width less its body (two people still pass each
    other in a corridor: in a 1.2 m corridor 0.35 m, in a 1 m door the body), never so large that it
    already overlaps another walker's (half their distance), and it fades to the body as the walker
    comes within its comfort radius of someone standing (people step close to others waiting at a
    counter). Never below the body radius; standing people keep their body radius.

    Compiled (numba), called every frame; the numpy form
    (:func:`song.pipeline.crowd._avoidance_reference.personal_radii_reference`) is its test twin.
    """
    radii = np.ascontiguousarray(radii, np.float64)
    if np.ndim(comfort_radius) == 0:
        comfort = np.full(radii.shape, float(comfort_radius))
    else:
        comfort = np.ascontiguousarray(comfort_radius, np.float64)
    return _personal_kernel(
        np.ascontiguousarray(positions, np.float64),
        radii,
        np.ascontiguousarray(walking, np.bool_),
        np.ascontiguousarray(half_width, np.float64),
        comfort,
        PERSONAL_MARGIN_M,
    )


@numba.njit(cache=True, nogil=True)
def _room(x, y, grid, ox, oy, res):  # pragma: no cover
    """``grid``'s value at the cell holding (x, y) (:meth:`WallDistance._cells`)."""
    rows, cols = grid.shape
    col = min(max(int((x - ox) / res), 0), cols - 1)
    row = min(max(int(rows - (y - oy) / res), 0), rows - 1)
    return grid[row, col]


@numba.njit(cache=True, nogil=True)
def _orca_velocities(
    positions, velocities, preferred, radii, max_speeds, held_up, field, thickness, frame, comfort, reach, tail
):  # pragma: no cover
    """ORCA's new velocities with personal space, as :meth:`OrcaAvoidance.velocities` documents.

    ``frame`` is the grids' ``(origin x, origin y, resolution)``; ``comfort`` is ``(comfort distance,
    wall comfort, anticipation horizon, obstacle time horizon)``; ``tail`` is :func:`song.pipeline.crowd.orca.
    kernel_tail`. One compiled call per frame (as numpy calls the inputs alone were ~30 dispatches).
    """
    ox, oy, res = frame
    distance, wall_comfort, horizon, horizon_obst = comfort
    n = len(positions)
    half_width, wall_radii, personal_comfort = np.empty(n), np.empty(n), np.empty(n)
    gain = np.empty(n)
    for i in range(n):
        x, y = positions[i, 0], positions[i, 1]
        ax, ay = x + preferred[i, 0] * horizon_obst, y + preferred[i, 1] * horizon_obst
        wall = min(_room(x, y, field, ox, oy, res), _room(ax, ay, field, ox, oy, res))
        half_width[i] = min(_room(x, y, thickness, ox, oy, res), _room(ax, ay, thickness, ox, oy, res))
        top = max(max_speeds[i], 1e-9)
        # the wall comfort fades as a walker slows down to arrive (people step close to a counter or desk)
        pace = min(np.hypot(preferred[i, 0], preferred[i, 1]) / top, 1.0)
        wall_radii[i] = max(min(wall - ROOM_MARGIN_M, radii[i] + wall_comfort * pace), radii[i])
        # personal space shrinks as a walker is held up (people accept closer passes in a jam), not while
        # it only slows down to let someone pass
        going = 1.0 - HELD_UP_GIVE * min(max(held_up[i] - HELD_UP_S, 0.0) / HELD_UP_S, 1.0)
        personal_comfort[i] = radii[i] + (0.5 * distance - radii[i]) * going
        gain[i] = ANTICIPATION_GAIN * swerve_room(half_width[i], radii[i], distance)
    bent = preferred
    if n >= 2:
        bent = _anticipate_kernel(positions, velocities, preferred, distance, horizon, reach, gain,
                                  ANTICIPATION_MARGIN_M)  # fmt: skip
    personal = _personal_kernel(positions, radii, max_speeds > 0, half_width, personal_comfort, PERSONAL_MARGIN_M)
    return step_kernel(positions, velocities, bent, personal, wall_radii, max_speeds, *tail)


def orca_walls(mesh: Navmesh) -> ObstacleSet | None:
    """ORCA walls: the mesh grown back by its agent radius (+ a 5 mm margin), in RVO2 vertex order."""
    rings = obstacle_rings(mesh, mesh.params.agent_radius + WALL_MARGIN_M)
    return build_obstacles(rings) if rings else None


class OrcaAvoidance:
    """ORCA with personal space (see the module docstring)."""

    name = "orca"

    def __init__(self, mesh: Navmesh, cfg: CrowdConfig) -> None:
        self.params = OrcaParams(
            1.0 / cfg.fps,
            cfg.neighbor_dist_m,
            cfg.max_neighbors,
            cfg.time_horizon_s,
            cfg.time_horizon_obst_s,
            static_full_responsibility=True,
            keep_pace=True,
        )
        self.walls = orca_walls(mesh)
        self.wall_distance = WallDistance(mesh)
        self.comfort, self.wall_comfort = cfg.comfort_distance_m, cfg.wall_comfort_m
        p = self.wall_distance.params
        self._constants = (  # what the compiled step takes besides the pedestrians and the grids, built once
            (float(p.origin[0]), float(p.origin[1]), float(p.resolution)),
            (self.comfort, self.wall_comfort, cfg.anticipation_s, self.params.time_horizon_obst),
            self.params.neighbor_dist,
            kernel_tail(self.walls, self.params),
        )

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
        held_up: np.ndarray,
    ) -> np.ndarray:
        """ORCA's new velocities with personal-space radii (see :func:`song.pipeline.crowd.orca.orca_step`)."""
        # the room a walker has now and where its preferred velocity takes it within the obstacle horizon:
        # the comfort shrinks before a narrowing, so that ORCA's wall never holds a walker at its entrance
        upto = 0.5 * self.comfort + (float(radii.max()) if len(radii) else 0.0)
        return _orca_velocities(
            np.ascontiguousarray(positions, np.float64),
            np.ascontiguousarray(velocities, np.float64),
            np.ascontiguousarray(preferred, np.float64),
            np.ascontiguousarray(radii, np.float64),
            np.ascontiguousarray(max_speeds, np.float64),
            np.ascontiguousarray(held_up, np.float64),
            self.wall_distance.field,
            self.wall_distance.thickness(upto),
            *self._constants,
        )


class SocialForceAvoidance:
    """Helbing–Molnár social forces with Moussaïd et al.'s pedestrian interaction (module docstring)."""

    name = "social_force"

    def __init__(self, mesh: Navmesh, cfg: CrowdConfig) -> None:
        self.dt = 1.0 / cfg.fps
        self.wall_distance = WallDistance(mesh)
        self.wall_comfort = cfg.wall_comfort_m
        rings = obstacle_rings(mesh, mesh.params.agent_radius)
        segments = [np.stack([ring, np.roll(ring, -1, axis=0)], axis=1) for ring in rings]
        self.segments = np.concatenate(segments) if segments else np.zeros((0, 2, 2))

    @property
    def neighbor_dist(self) -> float:
        """Agents farther apart than this cannot affect each other's answer, m."""
        return SF_RANGE_M

    def _wall_force(self, positions: np.ndarray, radii: np.ndarray, pace: np.ndarray) -> np.ndarray:
        """Repulsion from the nearest wall point, decaying beyond the body plus the wall comfort.

        Both fade with ``pace`` (preferred over top speed): someone slowing down to arrive at a counter
        steps close to it.
        """
        force = np.zeros_like(positions)
        near = np.flatnonzero(self.wall_distance.at(positions) < radii + self.wall_comfort + 5 * SF_WALL_RANGE_M)
        if not len(near) or not len(self.segments):
            return force
        a, b = self.segments[:, 0], self.segments[:, 1]
        ab = b - a
        p = positions[near][:, None, :]
        t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
        closest = a + t[..., None] * ab
        away = p - closest
        dist = np.hypot(away[..., 0], away[..., 1])
        k = dist.argmin(axis=1)
        d = dist[np.arange(len(near)), k]
        normal = away[np.arange(len(near)), k] / np.maximum(d, 1e-9)[:, None]
        gap = d - radii[near] - self.wall_comfort * pace[near]
        fade = np.maximum(2.0 * pace[near] - 1.0, 0.0)  # gone in the last r of an arrival
        force[near] = (SF_WALL_STRENGTH * fade * np.exp(-gap / SF_WALL_RANGE_M))[:, None] * normal
        return force

    def velocities(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        preferred: np.ndarray,
        radii: np.ndarray,
        max_speeds: np.ndarray,
        held_up: np.ndarray,
    ) -> np.ndarray:
        """One explicit Euler step of the forces; speeds clamped to the limits."""
        pace = np.minimum(np.hypot(preferred[:, 0], preferred[:, 1]) / np.maximum(max_speeds, 1e-9), 1.0)
        force = (preferred - velocities) / SF_RELAXATION_S + self._wall_force(positions, radii, pace)
        n = len(positions)
        if n > 1:
            rel = positions[None, :, :] - positions[:, None, :]  # i → j
            dist = np.hypot(rel[..., 0], rel[..., 1])
            np.fill_diagonal(dist, np.inf)
            e = rel / np.maximum(dist, 1e-9)[..., None]
            interaction = SF_LAMBDA * (velocities[:, None, :] - velocities[None, :, :]) + e
            size = np.maximum(np.hypot(interaction[..., 0], interaction[..., 1]), 1e-9)
            t = interaction / size[..., None]
            normal = np.stack([-t[..., 1], t[..., 0]], axis=-1)  # left normal of t
            theta = np.arctan2(t[..., 0] * e[..., 1] - t[..., 1] * e[..., 0], (t * e).sum(-1))  # from t to e
            b = SF_GAMMA * size
            decel = -np.exp(-dist / b - (SF_N_PRIME * b * theta) ** 2)
            turn = -np.sign(theta) * np.exp(-dist / b - (SF_N * b * theta) ** 2)
            pair = SF_STRENGTH * (decel[..., None] * t + turn[..., None] * normal)
            pair[dist > SF_RANGE_M] = 0.0
            force += pair.sum(axis=1)
        new = velocities + self.dt * force
        speed = np.hypot(new[:, 0], new[:, 1])
        scale = np.minimum(1.0, max_speeds / np.maximum(speed, 1e-12))
        return new * scale[:, None]


plugins.add("avoidance", "orca", OrcaAvoidance)
plugins.add("avoidance", "social_force", SocialForceAvoidance)


def make_avoidance(mesh: Navmesh, cfg: CrowdConfig) -> LocalAvoidance:
    """The model named by ``cfg.avoidance`` (a registered ``avoidance`` plugin) for ``mesh``."""
    return plugins.lookup("avoidance", cfg.avoidance)(mesh, cfg)
