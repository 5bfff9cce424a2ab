"""Joint crowd simulation at 30 FPS with DetourCrowd's structure (DESIGN §5.2).

Per pedestrian: a path corridor (grid shortest path over legal centres, string-pulled by line of
sight to corner points), steering toward the next visible corner (turn anticipation: a corner is
skipped as soon as the one after it is visible), slow-down within 2r of the goal, ORCA velocity
selection among all pedestrians, an acceleration clamp, moves constrained to the walkable area
(sliding along walls), overlap resolution passes, and stall detection (no progress for ~2 s →
replan; still stuck → the pedestrian is removed and the crowd re-simulated without it).

Pedestrians exist for the whole scenario: they stand at their start until their departure time and
at their goal after arriving, and others avoid them while they stand.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from song.config import CrowdConfig
from song.geometry.gridpath import GridGraph, distances_from, grid_graph, line_of_sight, path_cells, shortcut
from song.pipeline.crowd.orca import OrcaParams, orca_step
from song.pipeline.intents.model import Intent
from song.pipeline.intents.navigation import Walkable

ARRIVE_M = 0.05
CHECK_EVERY = 10  # frames between line-of-sight checks (turn anticipation, off-corridor detection): 1/3 s
CORNER_REACHED_M = 0.02  # close enough to a corner to head for the next one (the segment after it is legal)
PROGRESS_M = 0.1  # a pedestrian that gets no closer than this in stall_time_s is stalled
HEADING_SMOOTHING = 0.15  # EMA weight of the newest velocity in the heading estimate
STAND_SPEED = 0.05  # below this the heading is held
OVERLAP_PASSES = 3
MAX_RETRIES = 3


@dataclass
class CrowdPlan:
    """Joint trajectories of the kept pedestrians.

    Attributes:
        ped_ids: (P,) int. xy: (P, F, 2) m. yaw: (P, F) rad. speed: (P, F) m/s. fps: frames per second.
        status: per pedestrian id: {"status": "arrived" | "removed" | "timeout", "reason", "arrival_s"}.
    """

    ped_ids: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    fps: int
    status: dict[int, dict] = field(default_factory=dict)


class _Corridors:
    """Shortest paths over the legal-centre grid, string-pulled to corners (world metres)."""

    def __init__(self, walk: Walkable) -> None:
        self.walk = walk
        self.mask = walk.main
        self.graph: GridGraph = grid_graph(self.mask)
        self.grid = walk.package.occupancy

    def cell(self, xy: np.ndarray) -> tuple[int, int]:
        rc = self.grid.to_cell(xy)
        if 0 <= rc[0] < self.mask.shape[0] and 0 <= rc[1] < self.mask.shape[1] and self.mask[tuple(rc)]:
            return int(rc[0]), int(rc[1])
        near = self.graph.cells[np.argmin(((self.graph.cells - rc) ** 2).sum(axis=1))]
        return int(near[0]), int(near[1])

    def corners(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        a, b = self.cell(start), self.cell(goal)
        # search no farther than a generous multiple of the straight distance first (cheap), then everywhere
        straight = float(np.hypot(a[0] - b[0], a[1] - b[1]))
        cells = None
        for limit in (2.0 * straight + 40.0, np.inf):
            dist, pred = distances_from(self.graph, a, with_path=True, limit=limit)
            cells = path_cells(self.graph, dist, pred, b)
            if cells is not None:
                break
        if cells is None:
            return None
        pts = self.grid.to_world(shortcut(self.mask, cells))
        pts[-1] = goal
        return pts[1:] if len(pts) > 1 else pts

    def visible(self, a: np.ndarray, b: np.ndarray) -> bool:
        return line_of_sight(self.mask, self.grid.to_cell(a), self.grid.to_cell(b))

    def legal(self, xy: np.ndarray) -> np.ndarray:
        return self.walk.on_main(xy)


def _remaining(path: np.ndarray | None, corner: int, pos: np.ndarray) -> float:
    """Path length still to walk: to the current corner, then along the remaining corners."""
    if path is None:
        return float("inf")
    rest = path[corner:]
    return float(np.linalg.norm(rest[0] - pos) + np.linalg.norm(np.diff(rest, axis=0), axis=1).sum())


def _simulate(intents: list[Intent], corridors: _Corridors, cfg: CrowdConfig, rng: np.random.Generator):
    n, fps = len(intents), cfg.fps
    dt = 1.0 / fps
    r = cfg.agent_radius_m
    params = OrcaParams(dt, cfg.neighbor_dist_m, cfg.max_neighbors, cfg.time_horizon_s)
    goal = np.array([i.goal_xy for i in intents], dtype=np.float64)
    pos = np.array([i.start_xy for i in intents], dtype=np.float64)
    jitter = rng.uniform(-cfg.start_jitter_m, cfg.start_jitter_m, (n, 2))
    pos = np.where(corridors.legal(pos + jitter)[:, None], pos + jitter, pos)
    speed_pref = np.array([i.speed for i in intents])
    depart = np.array([i.depart_time for i in intents])
    paths = [corridors.corners(pos[k], goal[k]) for k in range(n)]
    failed = {k: "no path" for k in range(n) if paths[k] is None}
    corner = np.zeros(n, dtype=np.int64)
    vel = np.zeros((n, 2))
    arrived = np.zeros(n, dtype=bool)
    arrival = np.full(n, np.nan)
    best = np.array([_remaining(paths[k], 0, pos[k]) for k in range(n)])
    last_progress = depart.copy()
    replanned = np.zeros(n, dtype=bool)
    heading = np.array(
        [np.arctan2(*(p[0] - s)[::-1]) if p is not None else 0.0 for p, s in zip(paths, pos, strict=True)]
    )
    smooth = np.zeros((n, 2))
    max_frames = int(cfg.max_duration_s * fps)
    out_xy, out_yaw, out_speed = [pos.copy()], [heading.copy()], [np.zeros(n)]
    stall_frames = cfg.stall_time_s
    for frame in range(1, max_frames + 1):
        t = frame * dt
        moving = (depart <= t) & ~arrived
        for k in failed:
            moving[k] = False
        pref = np.zeros((n, 2))
        for k in np.flatnonzero(moving):
            path = paths[k]
            while corner[k] < len(path) - 1 and (
                np.linalg.norm(path[corner[k]] - pos[k]) < 0.1
                or (frame % CHECK_EVERY == 0 and corridors.visible(pos[k], path[corner[k] + 1]))
            ):
                corner[k] += 1
            if frame % CHECK_EVERY == 0 and not corridors.visible(pos[k], path[corner[k]]):
                # pushed off the corridor: a short detour back to the current corner, then the old corridor
                detour = corridors.corners(pos[k], path[corner[k]])
                if detour is not None:
                    path = np.vstack([detour, path[corner[k] + 1 :]])
                    paths[k], corner[k] = path, 0
            to = path[corner[k]] - pos[k]
            d = np.linalg.norm(to)
            d_goal = np.linalg.norm(goal[k] - pos[k])
            desired = speed_pref[k] * min(1.0, d_goal / (2 * r))  # slow down within 2r of the goal
            desired = min(desired, d / dt)
            pref[k] = to / max(d, 1e-9) * desired
        new_vel = orca_step(pos, vel, pref, np.full(n, r), np.where(moving, speed_pref, 0.0), params)
        dv = new_vel - vel
        limit = cfg.max_accel_mps2 * dt
        norm = np.linalg.norm(dv, axis=1, keepdims=True)
        new_vel = vel + np.where(norm > limit, dv / np.maximum(norm, 1e-12) * limit, dv)
        new_vel[~moving] = 0.0
        step = new_vel * dt
        target = pos + step
        ok = corridors.legal(target)
        for k in np.flatnonzero(~ok & moving):  # slide along walls, else stay
            for candidate in (pos[k] + [step[k, 0], 0.0], pos[k] + [0.0, step[k, 1]]):
                if corridors.legal(candidate[None])[0]:
                    target[k] = candidate
                    break
            else:
                target[k] = pos[k]
        budget = speed_pref * dt * 1.005 - np.linalg.norm(target - pos, axis=1)
        for _ in range(OVERLAP_PASSES):
            diff = target[:, None, :] - target[None, :, :]
            dist = np.linalg.norm(diff, axis=-1)
            np.fill_diagonal(dist, np.inf)
            overlap = np.clip(2 * r + 0.002 - dist, 0.0, None)
            if not overlap.any():
                break
            push = (diff / np.maximum(dist, 1e-9)[..., None] * (0.5 * overlap)[..., None]).sum(axis=1)
            push[~moving] = 0.0  # standing pedestrians hold their place; walkers make room
            size = np.linalg.norm(push, axis=1)
            scale = np.minimum(1.0, np.maximum(budget, 0.0) / np.maximum(size, 1e-12))
            pushed = target + push * scale[:, None]
            legal = corridors.legal(pushed)
            budget -= np.where(legal, size * scale, 0.0)
            target = np.where(legal[:, None], pushed, target)
        vel = (target - pos) / dt
        pos = target
        d_goal = np.linalg.norm(goal - pos, axis=1)
        done = moving & (d_goal < ARRIVE_M)  # stands where it is (no snap: a snap would exceed its speed)
        arrived |= done
        arrival[done] = t
        remaining = np.array([_remaining(paths[k], corner[k], pos[k]) for k in range(n)])
        improved = moving & (remaining < best - PROGRESS_M)
        best = np.where(improved, remaining, best)
        last_progress = np.where(improved, t, last_progress)
        for k in np.flatnonzero(moving & ~done & (t - last_progress > stall_frames)):
            if replanned[k]:
                return None, {k: "stalled after replanning"}
            replanned[k] = True
            last_progress[k] = t
            new_path = corridors.corners(pos[k], goal[k])
            if new_path is not None:
                paths[k], corner[k] = new_path, 0
                best[k] = _remaining(new_path, 0, pos[k])
        smooth = (1 - HEADING_SMOOTHING) * smooth + HEADING_SMOOTHING * vel
        spd = np.linalg.norm(smooth, axis=1)
        heading = np.where(spd > STAND_SPEED, np.arctan2(smooth[:, 1], smooth[:, 0]), heading)
        out_xy.append(pos.copy())
        out_yaw.append(heading.copy())
        out_speed.append(np.linalg.norm(vel, axis=1))
        if (arrived | np.isin(np.arange(n), list(failed))).all():
            break
    if failed:
        return None, failed
    return (np.stack(out_xy, 1), np.stack(out_yaw, 1), np.stack(out_speed, 1), arrived, arrival), {}


def plan_crowd(intents: list[Intent], walk: Walkable, cfg: CrowdConfig, rng: np.random.Generator) -> CrowdPlan:
    """Simulate all pedestrians jointly; pedestrians that cannot be planned are removed with a reason."""
    corridors = _Corridors(walk)
    kept = list(intents)
    status: dict[int, dict] = {}
    for _ in range(MAX_RETRIES + len(intents)):
        if not kept:
            break
        result, failures = _simulate(kept, corridors, cfg, rng)
        if result is None:
            for k, reason in failures.items():
                status[kept[k].id] = {"status": "removed", "reason": reason, "arrival_s": None}
            kept = [intent for k, intent in enumerate(kept) if k not in failures]
            continue
        xy, yaw, speed, arrived, arrival = result
        for k, intent in enumerate(kept):
            ok = bool(arrived[k])
            status[intent.id] = {
                "status": "arrived" if ok else "timeout",
                "reason": "" if ok else "did not arrive within max_duration_s",
                "arrival_s": round(float(arrival[k]), 4) if ok else None,
            }
        ids = np.array([intent.id for intent in kept], dtype=np.int64)
        return CrowdPlan(ids, xy, yaw, speed, cfg.fps, status)
    return CrowdPlan(np.zeros(0, np.int64), np.zeros((0, 1, 2)), np.zeros((0, 1)), np.zeros((0, 1)), cfg.fps, status)
