"""The closed-loop episode runner (paper "Evaluation protocol").

Per control step: observe (the selected sensors) → act → clip to the robot's limits → integrate.
Static contact restores the last safe pose and counts C_obs (at δ_obs the episode fails); a robot
that has not moved for ``stuck_steps`` steps is also turned toward the most open direction of its
field of view. Any avatar collision (more than η_col Gaussian centres inside the robot volume) fails
the episode. Success when the goal is closer than the goal radius. Otherwise a time-out after T_max
steps; a policy that fails (raises, exits, runs too long, returns no command) ends it as ``error``.
Exactly one outcome per episode. Every parameter comes from ``episode.params`` (the release's
recorded values, or explicit overrides).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from song.datasets.bench.types import Episode, pedestrian_states
from song.runtime.avatars import AvatarCollider, make_collider
from song.runtime.guard import DEFAULT_STEP_TIMEOUT_S, PolicyFailure, as_command, call_policy, policy_view
from song.runtime.metrics import EpisodeMetrics, episode_metrics
from song.runtime.policies import Policy, policy_sensors
from song.runtime.reactive import ReactiveCrowd
from song.runtime.robot import Pose, clamp_command, integrate
from song.runtime.sensors import RobotView, SensorSuite
from song.runtime.world import StaticWorld

MOVED_EPS_M = 0.02  # "has not moved": less than this displacement over the last stuck_steps steps
OPEN_RANGE_M = 5.0  # ray length when looking for the most open direction


@dataclass
class EpisodeResult:
    """Outcome and log of one episode."""

    episode_id: str
    scene_id: str
    difficulty: str
    outcome: str
    steps: int
    obstacle_collisions: int
    max_gaussian_count: int
    trajectory: np.ndarray  # (K, 3) x, y, yaw
    nearest: np.ndarray  # (K,) nearest-avatar horizontal distance per pose, m
    metrics: EpisodeMetrics
    events: list[tuple[int, str]] = field(default_factory=list)
    error: str = ""  # why the policy failed the episode (outcome "error")


def _most_open_yaw(pose: Pose, world: StaticWorld, fov: float) -> float:
    angles = pose.yaw + np.linspace(-fov / 2, fov / 2, 15)
    ranges = world.cast(pose.xy, angles, OPEN_RANGE_M)
    return float(angles[int(np.argmax(ranges))])


class EpisodeRunner:
    """Steps one episode; used by :func:`run_episode` and the Gymnasium env."""

    def __init__(
        self,
        episode: Episode,
        collider: AvatarCollider,
        sensors: SensorSuite | None = None,
        crowd: ReactiveCrowd | None = None,
    ) -> None:
        """Ready to step ``episode`` from its start.

        ``crowd``: reactive pedestrians (an option, :mod:`song.runtime.reactive`); ``episode`` and
        ``collider`` must then be ``crowd.episode`` and a collider built on it (:func:`reactive_setup`).
        """
        self.episode = episode
        self.crowd = crowd
        self.cfg = episode.params.robot
        self.sensors = sensors if sensors is not None else SensorSuite.build(("state",), episode.params)
        self.world = crowd.world if crowd is not None else StaticWorld(episode.static_map)  # one clearance field
        self.collider = collider
        self.dt = 1.0 / self.cfg.control_hz
        self.max_yaw_rate = np.deg2rad(self.cfg.max_yaw_rate_deg_s)
        self.pose = Pose(float(episode.start_xy[0]), float(episode.start_xy[1]), float(episode.start_yaw))
        self.last_safe = self.pose
        self.command = np.zeros(2)
        self.step_index = 0
        self.c_obs = 0
        self.max_count = 0
        self.outcome: str | None = None
        self.poses = [self.pose]
        self.nearest = [self._nearest(self.time)]
        self.events: list[tuple[int, str]] = []
        self.error = ""
        self.sensors.reset(episode)

    @property
    def time(self) -> float:
        """Scenario time of the current step, s."""
        return self.episode.t0 + self.step_index * self.dt

    def _nearest(self, t: float) -> float:
        _, xy, _ = pedestrian_states(self.episode.pedestrians, t)
        return float(np.linalg.norm(xy - self.pose.xy, axis=1).min()) if len(xy) else float("inf")

    def view(self) -> RobotView:
        """What the sensors read at the current step."""
        return RobotView(self.time, self.pose, self.command.copy(), self.episode, self.world)

    def observation(self) -> dict[str, Any]:
        """The selected sensors' outputs at the current step."""
        return self.sensors.observe(self.view())

    def step(self, v: float, omega: float) -> str | None:
        """Apply one command; returns the outcome when the episode ends, else None."""
        if self.outcome is not None:
            raise RuntimeError("episode already ended")
        v, omega = clamp_command(v, omega, self.cfg.max_speed_mps, self.max_yaw_rate)
        self.command = np.array([v, omega])
        pose = integrate(self.pose, v, omega, self.dt)
        before = self.time
        self.step_index += 1
        if self.world.collides(pose.xy, self.cfg.radius_m)[()]:
            self.c_obs += 1
            self.events.append((self.step_index, "obstacle"))
            pose = self.last_safe
            window = self.poses[-self.cfg.stuck_steps :]
            if len(window) >= self.cfg.stuck_steps and np.linalg.norm(window[0].xy - pose.xy) < MOVED_EPS_M:
                pose = Pose(pose.x, pose.y, _most_open_yaw(pose, self.world, np.deg2rad(self.cfg.fov_deg)))
                self.events.append((self.step_index, "reorient"))
        else:
            self.last_safe = pose
        self.pose = pose
        self.poses.append(pose)
        if self.crowd is not None:  # the people near the robot react to where it is now and where it is going
            heading = np.array([np.cos(pose.yaw), np.sin(pose.yaw)])
            self.crowd.advance(before, self.time, pose.xy, v * heading)
        self.nearest.append(self._nearest(self.time))
        count = self.collider.count(self.time, pose.xy)
        self.max_count = max(self.max_count, count)
        if self.c_obs >= self.cfg.max_obstacle_collisions:
            self.outcome = "obstacle"
        elif count > self.cfg.eta_col:
            self.outcome = "human"
            self.events.append((self.step_index, "human"))
        elif np.linalg.norm(pose.xy - self.episode.goal_xy) < self.cfg.goal_radius_m:
            self.outcome = "success"
        elif self.step_index >= self.cfg.max_steps:
            self.outcome = "timeout"
        return self.outcome

    def fail(self, reason: str) -> None:
        """End the episode because the policy failed (outcome ``error``, the reason recorded)."""
        self.outcome = "error"
        self.error = reason
        self.events.append((self.step_index, "policy_error"))

    def result(self) -> EpisodeResult:
        """The episode's outcome, log and metrics (once it has ended)."""
        if self.outcome is None:
            raise RuntimeError("episode has not ended")
        traj = np.array([[p.x, p.y, p.yaw] for p in self.poses])
        nearest = np.array(self.nearest)
        metrics = episode_metrics(
            self.outcome,
            traj[:, :2],
            self.dt,
            self.episode.geodesic_distance,
            self.episode.optimal_time,
            nearest,
            self.cfg.psc_threshold_m,
            self.cfg.max_speed_mps,
        )
        return EpisodeResult(
            self.episode.episode_id,
            self.episode.scene_id,
            self.episode.difficulty,
            self.outcome,
            self.step_index,
            self.c_obs,
            self.max_count,
            traj,
            nearest,
            metrics,
            self.events,
            self.error,
        )


def reactive_setup(episode: Episode, reactive: bool = True) -> tuple[Episode, AvatarCollider, ReactiveCrowd | None]:
    """The episode, its collider and its online crowd (None for replay).

    For reactive pedestrians the episode comes back with its own copy of the tracks, the collider built on it.
    """
    if not reactive:
        return episode, make_collider(episode), None
    crowd = ReactiveCrowd(episode)
    return crowd.episode, make_collider(crowd.episode), crowd


def run_episode(
    episode: Episode,
    policy: Policy,
    collider: AvatarCollider,
    sensors: SensorSuite | None = None,
    on_step: Callable[[EpisodeRunner], None] | None = None,
    step_timeout_s: float | None = DEFAULT_STEP_TIMEOUT_S,
    crowd: ReactiveCrowd | None = None,
) -> EpisodeResult:
    """Run ``policy`` on ``episode`` until it ends; deterministic for a deterministic policy.

    ``sensors`` defaults to the ones the policy declares (:func:`song.runtime.policies.policy_sensors`).
    The policy's ``reset`` sees a read-only copy of what its sensors entitle it to
    (:func:`song.runtime.guard.policy_view`: never the pedestrians' tracks); if it raises, exits, runs past ``step_timeout_s``
    in one call or returns a malformed command, this episode ends with outcome ``error`` and the reason
    (:mod:`song.runtime.guard`).
    """
    sensors = sensors or SensorSuite.build(policy_sensors(policy), episode.params, max(64, len(episode.pedestrians)))
    runner = EpisodeRunner(episode, collider, sensors, crowd)
    try:
        call_policy(policy.reset, policy_view(episode, sensors.names), what="reset()", timeout_s=step_timeout_s)
        while runner.outcome is None:
            action = call_policy(policy.act, runner.observation(), what="act()", timeout_s=step_timeout_s)
            runner.step(*as_command(action))
            if on_step is not None:
                on_step(runner)
    except PolicyFailure as exc:
        runner.fail(str(exc))
    return runner.result()
