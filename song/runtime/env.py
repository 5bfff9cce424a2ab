"""Gymnasium environment wrapping the same closed loop as ``song eval`` (STYLE: honour the contract).

``reset(seed=..., options={"episode_id": ...})`` returns ``(obs, info)``; ``step`` returns the
five-tuple; ``terminated`` is True on success or a collision failure, ``truncated`` on the step
limit. Randomness (which episode when none is named) comes from ``self.np_random``. The env id
carries the benchmark format's major version: ``song/SongNav-v1``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from song.config import RobotConfig
from song.datasets.bench import open_benchmark
from song.datasets.bench.schema import SCHEMA_VERSION, schema_major
from song.errors import MissingDependencyError
from song.runtime.avatars import make_collider
from song.runtime.loop import EpisodeRunner
from song.runtime.observation import Observation, ScanConfig

ENV_ID = f"song/SongNav-v{schema_major(SCHEMA_VERSION)}"
GOAL_RANGE_M = 1000.0  # observation bound for the robot-frame goal (scenes are far smaller)

try:
    import gymnasium as gym
    from gymnasium import spaces
except ImportError:  # pragma: no cover - exercised only without the gym extra
    gym = None


def _require_gym() -> None:
    if gym is None:
        raise MissingDependencyError("gymnasium", "gym")


class SongNavEnv(gym.Env if gym is not None else object):  # type: ignore[misc]
    """Point-goal navigation among replayed pedestrians on one SONG release.

    Observation (dict): ``goal`` (2,) robot-frame goal, m; ``velocity`` (2,) last (v, ω);
    ``scan`` (n,) ranges, m. Action: Box [v, ω] within the robot's limits.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        bench: str,
        version: str | None = None,
        difficulty: str | None = None,
        robot: RobotConfig | None = None,
        scan: ScanConfig | None = None,
    ) -> None:
        _require_gym()
        self.bench = open_benchmark(bench, version)
        self.robot = robot or RobotConfig()
        self.scan = scan or ScanConfig()
        self.episode_ids = [e.episode_id for e in self.bench.episodes(difficulty=difficulty)]
        max_w = np.deg2rad(self.robot.max_yaw_rate_deg_s)
        self.action_space = spaces.Box(
            low=np.array([0.0, -max_w], dtype=np.float32),
            high=np.array([self.robot.max_speed_mps, max_w], dtype=np.float32),
            dtype=np.float32,
        )
        self.observation_space = spaces.Dict(
            {
                "goal": spaces.Box(-GOAL_RANGE_M, GOAL_RANGE_M, shape=(2,), dtype=np.float32),
                "velocity": spaces.Box(
                    low=np.array([0.0, -max_w], dtype=np.float32),
                    high=np.array([self.robot.max_speed_mps, max_w], dtype=np.float32),
                    dtype=np.float32,
                ),
                "scan": spaces.Box(0.0, self.scan.max_range_m, shape=(self.scan.n_rays,), dtype=np.float32),
            }
        )
        self.runner: EpisodeRunner | None = None

    def _obs(self, observation: Observation) -> dict[str, np.ndarray]:
        return {
            "goal": np.clip(observation.goal, -GOAL_RANGE_M, GOAL_RANGE_M).astype(np.float32),
            "velocity": observation.velocity.astype(np.float32),
            "scan": np.clip(observation.scan, 0.0, self.scan.max_range_m).astype(np.float32),
        }

    def _info(self) -> dict[str, Any]:
        runner = self.runner
        return {
            "episode_id": runner.episode.episode_id,
            "difficulty": runner.episode.difficulty,
            "obstacle_collisions": runner.c_obs,
            "outcome": runner.outcome,
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        episode_id = (options or {}).get("episode_id")
        if episode_id is None:
            episode_id = self.episode_ids[int(self.np_random.integers(len(self.episode_ids)))]
        episode = self.bench.episode(episode_id)
        self.runner = EpisodeRunner(episode, make_collider(episode, self.robot), self.robot, self.scan)
        return self._obs(self.runner.observation()), self._info()

    def step(self, action):
        if self.runner is None:
            raise RuntimeError("call reset() before step()")
        previous = np.linalg.norm(self.runner.pose.xy - self.runner.episode.goal_xy)
        outcome = self.runner.step(float(action[0]), float(action[1]))
        distance = np.linalg.norm(self.runner.pose.xy - self.runner.episode.goal_xy)
        reward = float(previous - distance) + (10.0 if outcome == "success" else 0.0)
        reward -= 10.0 if outcome in ("obstacle", "human") else 0.0
        terminated = outcome in ("success", "obstacle", "human")
        truncated = outcome == "timeout"
        observation = self.runner.observation()
        return self._obs(observation), reward, terminated, truncated, self._info()


def register() -> None:
    """Register :data:`ENV_ID` with Gymnasium (idempotent)."""
    _require_gym()
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="song.runtime.env:SongNavEnv")
