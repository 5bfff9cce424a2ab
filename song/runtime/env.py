"""Gymnasium environment wrapping the same closed loop as ``song eval`` (STYLE: honour the contract).

``reset(seed=..., options={"episode_id": ...})`` returns ``(obs, info)``; ``step`` returns the
five-tuple; ``terminated`` is True on success or a collision failure, ``truncated`` on the step
limit. Randomness (which episode when none is named) comes from ``self.np_random``. Observations are
a dict with one entry per selected sensor (:mod:`song.runtime.sensors`), and the robot's limits come
from the release. The env id carries the benchmark format's major version: ``song/SongNav-v1``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from song.datasets.bench import open_benchmark
from song.datasets.bench.schema import SCHEMA_VERSION, schema_major
from song.datasets.bench.types import RuntimeParams
from song.errors import MissingDependencyError
from song.runtime.ablation import without_avatars
from song.runtime.avatars import make_collider
from song.runtime.guard import PolicyFailure, as_command
from song.runtime.loop import EpisodeRunner
from song.runtime.sensors import SensorSuite, to_gym_space

ENV_ID = f"song/SongNav-v{schema_major(SCHEMA_VERSION)}"
SUCCESS_REWARD = 10.0  # added on success, subtracted on a collision failure (a convenience for RL)

try:
    import gymnasium as gym
except ImportError:  # pragma: no cover - exercised only without the gym extra
    gym = None


def _require_gym() -> None:
    if gym is None:
        raise MissingDependencyError("gymnasium", "gym")


class SongNavEnv(gym.Env if gym is not None else object):  # type: ignore[misc]
    """Point-goal navigation among replayed pedestrians on one SONG release.

    Args:
        bench: benchmark folder, ``DIR@X.Y.Z`` or a release folder.
        version: release version (latest when None).
        difficulty: only episodes of this difficulty.
        sensors: sensor names (default ``("state", "scan")``).
        params: runtime parameters to use instead of the release's (an explicit override).
        sensor_options: per-sensor keyword options.
        allow_modified: use a release edited since export.
        no_avatars: the avatar-free ablation: episodes without pedestrians (neither rendered nor colliding).

    Observation: ``{sensor name: output}``; action: Box [v, ω] within the robot's limits.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        bench: str,
        version: str | None = None,
        difficulty: str | None = None,
        sensors: tuple[str, ...] | list[str] | str = ("state", "scan"),
        params: RuntimeParams | None = None,
        sensor_options: dict[str, dict] | None = None,
        allow_modified: bool = False,
        no_avatars: bool = False,
    ) -> None:
        _require_gym()
        from gymnasium import spaces

        self.bench = open_benchmark(bench, version)
        self.bench.require_intact(allow_modified)  # a release edited after export is refused
        self.params = params or self.bench.params
        self.sensors = SensorSuite.build(sensors, self.params, self.bench.max_pedestrians, sensor_options)
        self.episode_ids = [e.episode_id for e in self.bench.episodes(difficulty=difficulty)]
        robot = self.params.robot
        max_w = np.deg2rad(robot.max_yaw_rate_deg_s)
        self.action_space = spaces.Box(
            low=np.array([0.0, -max_w], dtype=np.float32),
            high=np.array([robot.max_speed_mps, max_w], dtype=np.float32),
            dtype=np.float32,
        )
        self.observation_space = to_gym_space(self.sensors.space())
        self.runner: EpisodeRunner | None = None
        self.no_avatars = no_avatars

    def _info(self) -> dict[str, Any]:
        runner = self.runner
        return {
            "episode_id": runner.episode.episode_id,
            "difficulty": runner.episode.difficulty,
            "obstacle_collisions": runner.c_obs,
            "outcome": runner.outcome,
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode (``options["episode_id"]``, or one drawn with ``self.np_random``)."""
        super().reset(seed=seed)
        episode_id = (options or {}).get("episode_id")
        if episode_id is None:
            episode_id = self.episode_ids[int(self.np_random.integers(len(self.episode_ids)))]
        episode = dataclasses.replace(self.bench.episode(episode_id), params=self.params)
        if self.no_avatars:
            episode = without_avatars(episode)
        self.runner = EpisodeRunner(episode, make_collider(episode), self.sensors)
        return self.runner.observation(), self._info()

    def step(self, action):
        """Apply [v, ω]; reward = progress toward the goal, ±10 at a success / collision end.

        An action that is not two finite numbers ends the episode as ``error`` (terminated, the reason
        in ``info["error"]``), the rule ``song eval`` applies to a policy's malformed command.
        """
        if self.runner is None:
            raise RuntimeError("call reset() before step()")
        try:
            v, w = as_command(action)
        except PolicyFailure as exc:
            self.runner.fail(str(exc))
            return self.runner.observation(), 0.0, True, False, {**self._info(), "error": self.runner.error}
        previous = np.linalg.norm(self.runner.pose.xy - self.runner.episode.goal_xy)
        outcome = self.runner.step(v, w)
        distance = np.linalg.norm(self.runner.pose.xy - self.runner.episode.goal_xy)
        progress, terminal = reward_terms(float(previous), float(distance), outcome)
        reward = progress + terminal
        terminated = outcome in ("success", "obstacle", "human")
        truncated = outcome == "timeout"
        return self.runner.observation(), reward, terminated, truncated, self._info()


def reward_terms(previous_m: float, distance_m: float, outcome: str | None) -> tuple[float, float]:
    """A step's reward as ``(progress toward the goal, m; ±SUCCESS_REWARD at a success / collision end)``."""
    terminal = SUCCESS_REWARD if outcome == "success" else -SUCCESS_REWARD if outcome in ("obstacle", "human") else 0.0
    return previous_m - distance_m, terminal


def register() -> None:
    """Register :data:`ENV_ID` with Gymnasium (idempotent)."""
    _require_gym()
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="song.runtime.env:SongNavEnv")
