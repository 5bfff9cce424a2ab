"""Robot episode sampling in one scene: four modes, A* on the robot-inflated grid."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from song.config import GradingConfig
from song.datasets.scenes import ScenePackage
from song.geometry.astar import astar
from song.geometry.freespace import clearance_field, components
from song.geometry.gridpath import polyline_length, shortcut


@dataclass
class RobotMap:
    """Where the robot can be: free space inflated by its radius (A* runs on this grid)."""

    package: ScenePackage
    legal: np.ndarray
    clearance: np.ndarray
    xy: np.ndarray  # (n, 2) world centres of the legal cells
    labels: np.ndarray | None = None  # connected components of ``legal`` (cheap reachability test)

    @classmethod
    def build(cls, package: ScenePackage, radius: float) -> RobotMap:
        """Inflate by ``radius`` (the robot's radius plus the path's safety margin)."""
        grid = package.occupancy
        room = clearance_field(grid.free, grid.resolution)
        legal = room >= radius
        labels, _ = components(legal)  # 4-connected, as the A* (no corner cutting) moves
        return cls(package, legal, room, grid.to_world(np.argwhere(legal)), labels)

    def connected(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Same walkable component (no path search needed to reject the rest)."""
        ra, rb = self.package.occupancy.to_cell(np.stack([a, b]))
        return bool(self.labels[tuple(ra)] and self.labels[tuple(ra)] == self.labels[tuple(rb)])

    def plan(self, start: np.ndarray, goal: np.ndarray, max_length_m: float = np.inf) -> np.ndarray | None:
        """Smoothed A*-optimal path (K, 2) between two legal points, or None when unreachable.

        The search stops at ``max_length_m`` (paths longer than that are not wanted), which keeps
        queries cheap in large scenes; within the bound the result is exact.
        """
        grid = self.package.occupancy
        a, b = (tuple(int(v) for v in grid.to_cell(p)) for p in (start, goal))
        _, cells = astar(self.legal, a, b, limit=max_length_m / grid.resolution + 1.0)
        if cells is None:
            return None
        points = grid.to_world(shortcut(self.legal, cells))
        points[0], points[-1] = start, goal
        return points


@dataclass
class Crowd:
    """A scene's pedestrian trajectories: ids (P,), xy (P, F, 2) at ``fps`` from t = 0."""

    ids: np.ndarray
    xy: np.ndarray
    fps: int

    @property
    def duration(self) -> float:
        """Length of the scenario, s."""
        return self.xy.shape[1] / self.fps

    def at(self, t: np.ndarray) -> np.ndarray:
        """(K, P, 2) positions at times t (K,), holding the first/last frame outside the scenario."""
        frames = np.clip(np.round(np.asarray(t) * self.fps).astype(np.int64), 0, self.xy.shape[1] - 1)
        return np.transpose(self.xy[:, frames], (1, 0, 2))

    @functools.cached_property
    def walking(self) -> np.ndarray:
        """(P, F) bool: the pedestrian moves faster than ``WALKING_MPS`` at that frame."""
        if self.xy.shape[1] < 2:
            return np.zeros(self.xy.shape[:2], dtype=bool)
        speed = np.linalg.norm(np.diff(self.xy, axis=1), axis=-1) * self.fps
        return np.concatenate([speed[:, :1], speed], axis=1) > WALKING_MPS

    def walks(self, p: int) -> list[tuple[int, int]]:
        """Pedestrian p's walks: (first, last) frames of each walking stretch of at least ``MIN_WALK_S``."""
        edges = np.diff(np.concatenate([[0], self.walking[p].astype(np.int8), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True) if (b - a) / self.fps >= MIN_WALK_S]

    def circle(self) -> tuple[np.ndarray, float]:
        """Centre (2,) and radius (m) of the circle bounding every trajectory sample."""
        pts = self.xy.reshape(-1, 2)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre = 0.5 * (lo + hi)
        return centre, float(np.linalg.norm(pts - centre, axis=1).max())


def robot_positions(path: np.ndarray, speed: float, dt: float) -> np.ndarray:
    """Positions (K, 2) of a robot moving along ``path`` at constant ``speed``, sampled every ``dt``."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.arange(0.0, arc[-1] + 1e-9, speed * dt)
    if s[-1] < arc[-1]:
        s = np.append(s, arc[-1])
    return np.column_stack([np.interp(s, arc, path[:, 0]), np.interp(s, arc, path[:, 1])])


def pass_distances(path: np.ndarray, crowd: Crowd, t0: float, speed: float, walking_only: bool = False):
    """(K, P) horizontal distances between the robot moving along ``path`` from ``t0`` and each pedestrian.

    With ``walking_only``, distances to a pedestrian at frames where it is not walking are infinite.
    """
    robot = robot_positions(path, speed, 1.0 / crowd.fps)
    t = t0 + np.arange(len(robot)) / crowd.fps
    d = np.linalg.norm(crowd.at(t) - robot[:, None, :], axis=-1)
    if walking_only:
        frames = np.clip(np.round(t * crowd.fps).astype(np.int64), 0, crowd.xy.shape[1] - 1)
        d = np.where(crowd.walking[:, frames].T, d, np.inf)
    return d


def closest_pass(path: np.ndarray, crowd: Crowd, t0: float, speed: float) -> np.ndarray:
    """Per pedestrian, the closest horizontal distance to the robot moving along ``path`` from ``t0``."""
    return pass_distances(path, crowd, t0, speed).min(axis=0)


def subtended_deg(a: np.ndarray, b: np.ndarray, centre: np.ndarray) -> float:
    """Angle (deg) subtended at ``centre`` by points ``a`` and ``b`` (2,)."""
    u, v = a - centre, b - centre
    cos = float(u @ v / max(np.linalg.norm(u) * np.linalg.norm(v), 1e-12))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


WALKING_MPS = 0.2  # a pedestrian faster than this is walking (as in benchmarks/crowd_realism.py)
MIN_WALK_S = 2.0  # co/counter-directional episodes follow a walk of at least this long
WALK_SHARE = 0.5  # ... during which the reference pedestrian walks for this share of the shorter of both


class EpisodeSampler:
    """Bounded rejection sampling of (start, goal, t0) for one mode."""

    def __init__(self, robot: RobotMap, crowd: Crowd, cfg: GradingConfig, duration: float) -> None:
        self.robot, self.crowd, self.cfg = robot, crowd, cfg
        self.duration = duration
        self.centre, self.radius = crowd.circle()
        self.in_circle = robot.xy[np.linalg.norm(robot.xy - self.centre, axis=1) <= self.radius]

    def _near(self, point: np.ndarray, radius: float, rng: np.random.Generator) -> np.ndarray | None:
        near = self.robot.xy[np.linalg.norm(self.robot.xy - point, axis=1) <= radius]
        return near[int(rng.integers(len(near)))] if len(near) else None

    def _t0(self, rng: np.random.Generator, length: float) -> float:
        latest = max(0.0, self.duration - length / self.cfg.robot_speed_mps)
        return round(float(rng.uniform(0.0, latest)), 3)

    def _t0_during(self, rng: np.random.Generator, length: float, walk: tuple[int, int]) -> float | None:
        """A t0 at which the reference pedestrian walks during the robot's nominal traversal.

        It walks for at least ``WALK_SHARE`` of the shorter of its walk and the traversal; None when no
        such t0 fits in the scenario.
        """
        run = length / self.cfg.robot_speed_mps
        ts, te = walk[0] / self.crowd.fps, walk[1] / self.crowd.fps
        need = WALK_SHARE * min(run, te - ts)
        lo, hi = max(0.0, ts - run + need), min(max(0.0, self.duration - run), te - need)
        return round(float(rng.uniform(lo, hi)), 3) if hi >= lo else None

    def draw(self, mode: str, rng: np.random.Generator) -> tuple[dict | None, str]:
        """One episode of ``mode`` or (None, reason) after ``max_tries`` attempts."""
        cfg = self.cfg
        reason = "no candidate"
        for _ in range(cfg.max_tries):
            walk, ref = None, -1
            if mode in ("co_directional", "counter_directional"):
                ref = int(rng.integers(len(self.crowd.ids)))
                walks = self.crowd.walks(ref)
                if not walks:
                    reason = "the pedestrian never walks"
                    continue
                walk = walks[int(rng.integers(len(walks)))]
                a, b = self.crowd.xy[ref, walk[0]], self.crowd.xy[ref, walk[1]]
                if mode == "counter_directional":
                    a, b = b, a
                start, goal = self._near(a, cfg.near_ped_m, rng), self._near(b, cfg.near_ped_m, rng)
            else:
                if len(self.in_circle) < 2:
                    return None, "bounding circle holds no robot-traversable cells"
                start, goal = (self.in_circle[int(rng.integers(len(self.in_circle)))] for _ in range(2))
                if subtended_deg(start, goal, self.centre) <= cfg.min_angle_deg:
                    reason = "angle ≤ 90°"
                    continue
            if start is None or goal is None:
                reason = "no traversable cell near the pedestrian's endpoints"
                continue
            straight = float(np.linalg.norm(goal - start))  # a lower bound of L*: reject before searching
            if straight > cfg.max_path_m or not self.robot.connected(start, goal):
                reason = "goal unreachable or farther than the longest allowed path"
                continue
            # the grid path is at least as long as the smoothed one: bound the search a little beyond the cap
            path = self.robot.plan(start, goal, max_length_m=1.5 * cfg.max_path_m)
            if path is None:
                reason = "goal unreachable from start within the path-length bound"
                continue
            length = polyline_length(path)
            if not cfg.min_path_m <= length <= cfg.max_path_m:
                reason = f"path length {length:.1f} m outside [{cfg.min_path_m}, {cfg.max_path_m}]"
                continue
            t0 = self._t0(rng, length) if walk is None else self._t0_during(rng, length, walk)
            if t0 is None:
                reason = "the pedestrian's walk and the robot's traversal do not fit in the scenario together"
                continue
            if np.linalg.norm(self.crowd.at(np.array([t0]))[0] - start, axis=1).min() < cfg.start_clearance_m:
                reason = "a pedestrian stands at the start at t0"
                continue
            meet = None
            if mode != "random":  # the reference pedestrian and when the robot passes it
                d = pass_distances(path, self.crowd, t0, cfg.robot_speed_mps, walking_only=mode == "encounter")
                if mode == "encounter":
                    ref = int(np.argmin(d.min(axis=0)))
                    if d[:, ref].min() > cfg.encounter_pass_m:
                        reason = "robot never passes within 1 m of a walking pedestrian"
                        continue
                meet = round(t0 + int(np.argmin(d[:, ref])) / self.crowd.fps, 3)
            return {
                "start": start,
                "goal": goal,
                "path": path,
                "length": length,
                "t0": t0,
                "reference_ped": int(self.crowd.ids[ref]) if ref >= 0 else -1,
                "encounter_time": meet,
            }, ""
        return None, reason
