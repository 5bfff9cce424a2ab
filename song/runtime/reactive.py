"""Reactive pedestrians (an option): people near the robot avoid it, then rejoin their recorded ways.

Replay is the official protocol (the paper's pedestrians ignore the robot: its limitation 2). With this
option an episode is no longer a pure replay: each step, every pedestrian within ``radius`` of the robot
(and anyone still off its recorded track) is simulated online for that step. It prefers its recorded
velocity plus a pull back onto its recorded position (``RETURN_S``), and keeps out of the robot's way by
ORCA (van den Berg et al. 2011) with the robot as an agent that does not yield: one half-plane from the
robot's position and velocity, the pedestrian taking all of the avoidance, solved with its speed
limit as in RVO2's one-constraint linear program. Its step must keep its body off walls and off other
pedestrians; when it would not, it takes its recorded step from where it is, or stands for that step
(one still on its recording always may take its recorded step: that is the replay).

The displacement from the recording is written into the episode's own copy of the tracks (from the
current sample on), so every consumer (collisions, sensors, rendering, metrics) sees the same displaced
people. The avatars show their recorded full-body motion, time-warped to how far along its recorded way
each has come (stopped by the robot, a walker holds its pose; hurrying back, it plays its gait faster)
and moved from there to where it is. Deterministic: no randomness, the same commands give the same
crowd.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from song.datasets.bench.types import Episode, pedestrian_states
from song.runtime.world import StaticWorld

REACT_RADIUS_M = 3.0  # pedestrians this close to the robot react to it
RETURN_S = 1.5  # an offset from the recorded track is taken back at offset / RETURN_S
TIME_HORIZON_S = 3.0  # ORCA's horizon against the robot
MARGIN_M = 0.05  # kept beyond body contact with the robot
MAX_ACCEL = 2.0  # m/s², the crowd's acceleration limit
MIN_SPEED_LIMIT = 0.8  # m/s: even someone standing may step out of the robot's way this fast
SPEED_FACTOR = 1.3  # ... and a walker may speed up to this much of its recorded speed
SETTLED_M = 1e-4  # an offset below this is gone: the pedestrian is back on its recording
MAX_WARP = 2.0  # the recorded motion plays at most this much faster than real time (catching up) ...
WARP_SAMPLES = 21  # ... and is searched at this many times per step (0 included: stopped, it holds its pose)


def orca_line(
    p: np.ndarray, v: np.ndarray, other_p: np.ndarray, other_v: np.ndarray, radius: float, tau: float, dt: float
):
    """ORCA's half-plane for an agent at ``p`` with velocity ``v`` against one that does not yield.

    Returns ``(point (2,), direction (2,))``: a velocity x is allowed when it lies left of the line,
    ``det(direction, point − x) ≤ 0`` (RVO2's convention); the agent takes all of the avoidance.
    """
    rel_p, rel_v = other_p - p, v - other_v
    dist_sq = float(rel_p @ rel_p)
    r_sq = radius * radius
    if dist_sq > r_sq:
        w = rel_v - rel_p / tau
        w_len_sq = float(w @ w)
        dot1 = float(w @ rel_p)
        if dot1 < 0.0 and dot1 * dot1 > r_sq * w_len_sq:  # the cut-off circle
            w_len = math.sqrt(w_len_sq)
            unit = w / w_len
            direction = np.array([unit[1], -unit[0]])
            u = (radius / tau - w_len) * unit
        else:  # a leg of the cone
            leg = math.sqrt(dist_sq - r_sq)
            if rel_p[0] * w[1] - rel_p[1] * w[0] > 0.0:
                direction = np.array([rel_p[0] * leg - rel_p[1] * radius, rel_p[0] * radius + rel_p[1] * leg]) / dist_sq
            else:
                direction = (
                    -np.array([rel_p[0] * leg + rel_p[1] * radius, -rel_p[0] * radius + rel_p[1] * leg]) / dist_sq
                )
            u = float(rel_v @ direction) * direction - rel_v
    else:  # already overlapping: get out within this step
        w = rel_v - rel_p / dt
        w_len = max(math.sqrt(float(w @ w)), 1e-9)
        unit = w / w_len
        direction = np.array([unit[1], -unit[0]])
        u = (radius / dt - w_len) * unit
    return v + u, direction


def solve_one(point: np.ndarray, direction: np.ndarray, preferred: np.ndarray, limit: float) -> np.ndarray:
    """The velocity nearest ``preferred`` within speed ``limit`` on the allowed side of one ORCA line.

    RVO2's ``linearProgram1`` for a single line; when the line misses the speed circle, the allowed
    velocity nearest the line within the limit (straight away from the robot).
    """
    speed = float(np.hypot(*preferred))
    x = preferred * (limit / speed) if speed > limit else preferred.copy()
    if direction[0] * (point[1] - x[1]) - direction[1] * (point[0] - x[0]) <= 0.0:
        return x
    dot = float(point @ direction)
    disc = dot * dot + limit * limit - float(point @ point)
    if disc < 0.0:
        normal = np.array([-direction[1], direction[0]])  # toward the allowed side
        return normal * limit
    root = math.sqrt(disc)
    t = float(np.clip(direction @ (preferred - point), -dot - root, -dot + root))
    return point + t * direction


class ReactiveCrowd:
    """The online part of an episode's crowd; build it, use :attr:`episode`, call :meth:`advance` each step."""

    def __init__(self, episode: Episode, world: StaticWorld | None = None, radius: float = REACT_RADIUS_M) -> None:
        self.radius = radius
        self.body = float(episode.params.pedestrian_radius_m)
        self.robot_radius = float(episode.params.robot.radius_m)
        self.world = world if world is not None else StaticWorld(episode.static_map)
        self.recorded = list(episode.pedestrians)  # the release's tracks, as replay reads them
        tracks = [
            dataclasses.replace(track, xy=track.xy.copy(), shift=np.zeros_like(track.xy), motion_t=track.t.copy())
            for track in episode.pedestrians
        ]
        self.episode = dataclasses.replace(episode, pedestrians=tracks)
        self.offset = np.zeros((len(tracks), 2))
        self.velocity = np.zeros((len(tracks), 2))  # the online velocity of those reacting, m/s
        self.motion_t = np.full(len(tracks), float(episode.t0))  # the recorded motion's time each one shows, s

    def _recorded_xy(self, k: int, times) -> np.ndarray:
        """Pedestrian k's recorded position(s) at ``times`` (clamped to its track's ends, as replay is)."""
        track = self.recorded[k]
        return np.stack([np.interp(times, track.t, track.xy[:, 0]), np.interp(times, track.t, track.xy[:, 1])], -1)

    def advance(self, t0: float, t1: float, robot_xy: np.ndarray, robot_velocity: np.ndarray) -> None:
        """Move the crowd from t0 to t1 (one control step) around the robot at ``robot_xy``."""
        dt = t1 - t0
        if dt <= 0.0 or not len(self.offset):
            return
        here = pedestrian_states(self.recorded, t0)[1] + self.offset
        near = np.hypot(*(here - robot_xy).T) < self.radius
        reacting = near | (np.hypot(*self.offset.T) > SETTLED_M)
        self.motion_t[~reacting] = t1  # on their recordings: they show the recorded motion of now
        if not reacting.any():
            return
        _, recorded, recorded_v = pedestrian_states(self.recorded, t1)
        after = recorded + self.offset
        combined = self.body + self.robot_radius + MARGIN_M
        for k in np.flatnonzero(reacting):
            rec1, vel1 = recorded[k], recorded_v[k]
            preferred = vel1 - self.offset[k] / RETURN_S
            limit = max(SPEED_FACTOR * float(np.hypot(*vel1)), MIN_SPEED_LIMIT)
            if near[k]:
                point, direction = orca_line(
                    here[k], self.velocity[k], robot_xy, robot_velocity, combined, TIME_HORIZON_S, dt
                )
                wanted = solve_one(point, direction, preferred, limit)
            else:
                wanted = preferred * min(1.0, limit / max(float(np.hypot(*preferred)), 1e-9))
            change = wanted - self.velocity[k]
            size = float(np.hypot(*change))
            if size > MAX_ACCEL * dt:
                wanted = self.velocity[k] + change * (MAX_ACCEL * dt / size)
            others = np.delete(after, k, axis=0)
            candidate = here[k]  # where it stands, when neither step is free
            on_recording = float(np.hypot(*self.offset[k])) <= SETTLED_M
            for step in (wanted, vel1):
                # on its recording, the recorded step is the replay's: taken even where the recording
                # itself comes closer to a wall or someone than a body (a release's tracks are as they are)
                if self._free(here[k] + step * dt, others) or (step is vel1 and on_recording):
                    candidate = here[k] + step * dt
                    break
            self.velocity[k] = (candidate - here[k]) / dt
            self.offset[k] = candidate - rec1
            if float(np.hypot(*self.offset[k])) <= SETTLED_M:
                self.offset[k] = 0.0
                self.motion_t[k] = t1
            else:
                self.motion_t[k] = self._progress(int(k), self.motion_t[k], t0, t1, candidate)
            after[k] = candidate
            self._write(int(k), t1)

    def _free(self, xy: np.ndarray, others: np.ndarray) -> bool:
        """A body at ``xy`` is off walls and off every other pedestrian (to 1 cm)."""
        if self.world.collides(xy, self.body)[()]:
            return False
        return not len(others) or float(np.hypot(*(others - xy).T).min()) >= 2 * self.body - 0.01

    def _progress(self, k: int, shown: float, t0: float, t1: float, where: np.ndarray) -> float:
        """The recorded motion's time pedestrian k shows at t1, having shown ``shown`` at t0, now at ``where``.

        The body's gait follows how far along its recorded way it has come: the time, among
        ``WARP_SAMPLES`` from ``shown`` to ``shown`` + ``MAX_WARP`` · (t1 − t0), whose recorded position
        is nearest ``where`` (ties, as where the recording stands still: the one nearest t1 it can reach).
        Stopped by the robot it holds its pose; hurrying back it plays its motion faster.
        """
        dt = t1 - t0
        times = np.linspace(shown, shown + MAX_WARP * dt, WARP_SAMPLES)
        gaps = np.hypot(*(self._recorded_xy(k, times) - where).T)
        cost = gaps + 0.01 * np.abs(times - min(t1, shown + MAX_WARP * dt))
        return float(times[int(np.argmin(cost))])

    def _write(self, k: int, t1: float) -> None:
        """Pedestrian k's displaced track from the sample at or before t1 on (what everyone reads from now on).

        Its position, and what its avatar shows: the recorded motion at ``motion_t`` moved by ``shift``
        (at later samples, as if it followed its recording's pace from here; the next step rewrites them).
        """
        track, recorded = self.episode.pedestrians[k], self.recorded[k]
        i = max(int(np.searchsorted(track.t, t1, side="right")) - 1, 0)
        track.xy[i:] = recorded.xy[i:] + self.offset[k]
        shown = self.motion_t[k]
        track.motion_t[i:] = shown + (track.t[i:] - t1)
        track.shift[i:] = self.offset[k] + self._recorded_xy(k, t1) - self._recorded_xy(k, shown)
