"""Gymnasium environment wrapping the same closed loop as ``song eval`` (STYLE: honour the contract).

``reset(seed=..., options={"episode_id": ...})`` returns ``(obs, info)``; ``step`` returns the
five-tuple; ``terminated`` is True on success or a collision failure, ``truncated`` on the step
limit. Randomness (which episode when none is named) comes from ``self.np_random``. Observations are
a dict with one entry per selected sensor (:mod:`song.runtime.sensors`), and the robot's limits come
from the release. The env id carries the benchmark format's major version: ``song/SongNav-v1``; it is
registered when this module is imported, so ``gym.make("song.runtime.env:song/SongNav-v1", bench=...)``
works on its own. :func:`make` adds the release's step limit as ``max_episode_steps``;
:func:`make_vector` makes a Gymnasium vector env of several copies (a process each);
:class:`SongVectorEnv` steps several in one process and renders their cameras in one call.
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
from song.runtime.guard import PolicyFailure, as_command
from song.runtime.loop import EpisodeRunner, reactive_setup
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
        reactive: reactive pedestrians: those near the robot avoid it (:mod:`song.runtime.reactive`; an
            option, not the official replay protocol).
        resolution: (width, height) of the camera sensors (default: the release's, 960×540).
        render_backend: the renderer of the camera sensors (``auto``, ``numba``, ``gsplat``, ...).
        render_mode: ``"rgb_array"``: :meth:`render` returns the first-person RGB | depth | top-down map
            picture of ``song viz pov``; None renders nothing.

    Observation: ``{sensor name: output}``; action: Box [v, ω] within the robot's limits. Episodes end
    at the release's step limit (``truncated``); :func:`make` also registers it as ``max_episode_steps``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

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
        reactive: bool = False,
        resolution: tuple[int, int] | None = None,
        render_backend: str = "auto",
        render_mode: str | None = None,
    ) -> None:
        _require_gym()
        from gymnasium import spaces

        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode {render_mode!r}: use one of {self.metadata['render_modes']} or None")
        self.render_mode = render_mode
        self.bench = open_benchmark(bench, version)
        self.bench.require_intact(allow_modified)  # a release edited after export is refused
        self.params = params or self.bench.params
        options = {name: dict(values) for name, values in (sensor_options or {}).items()}
        camera = options.setdefault("camera", {})
        camera.setdefault("backend", render_backend)
        if resolution is not None:
            camera.update(width=int(resolution[0]), height=int(resolution[1]))
        self.camera = dict(camera)
        self.sensors = SensorSuite.build(sensors, self.params, self.bench.max_pedestrians, options)
        self.metadata = {**self.metadata, "render_fps": float(self.params.robot.control_hz)}
        self._pictures = None
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
        self.reactive = reactive

    def render(self):
        """The current view as ``song viz pov`` draws it: RGB | depth | top-down map (``rgb_array``)."""
        if self.render_mode is None or self.runner is None:
            return None
        if self._pictures is None:
            from song.runtime.pictures import PovPictures

            self._pictures = PovPictures(self.params, self.bench.max_pedestrians, self.camera)
        return self._pictures.frame(self.runner, self.runner.observation())

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
        self._start(seed, options)
        return self.runner.observation(), self._info()

    def _start(self, seed: int | None, options: dict[str, Any] | None) -> None:
        super().reset(seed=seed)
        episode_id = (options or {}).get("episode_id")
        if episode_id is None:
            episode_id = self.episode_ids[int(self.np_random.integers(len(self.episode_ids)))]
        episode = dataclasses.replace(self.bench.episode(episode_id), params=self.params)
        if self.no_avatars:
            episode = without_avatars(episode)
        episode, collider, crowd = reactive_setup(episode, self.reactive)
        self.runner = EpisodeRunner(episode, collider, self.sensors, crowd)

    def step(self, action):
        """Apply [v, ω]; reward = progress toward the goal, ±10 at a success / collision end.

        An action that is not two finite numbers ends the episode as ``error`` (terminated, the reason
        in ``info["error"]``), the rule ``song eval`` applies to a policy's malformed command.
        """
        reward, terminated, truncated, info = self._advance(action)
        return self.runner.observation(), reward, terminated, truncated, info

    def _advance(self, action) -> tuple[float, bool, bool, dict[str, Any]]:
        if self.runner is None:
            raise RuntimeError("call reset() before step()")
        try:
            v, w = as_command(action)
        except PolicyFailure as exc:
            self.runner.fail(str(exc))
            return 0.0, True, False, {**self._info(), "error": self.runner.error}
        previous = np.linalg.norm(self.runner.pose.xy - self.runner.episode.goal_xy)
        outcome = self.runner.step(v, w)
        distance = np.linalg.norm(self.runner.pose.xy - self.runner.episode.goal_xy)
        progress, terminal = reward_terms(float(previous), float(distance), outcome)
        terminated = outcome in ("success", "obstacle", "human")
        return progress + terminal, terminated, outcome == "timeout", self._info()

    def _prerender_jobs(self) -> list[tuple]:
        """This env's camera views at the current step, for :func:`song.runtime.vision.render_together`."""
        view = self.runner.view()
        command = (float(view.command[0]), float(view.command[1]))
        return [(sv, view.pose, view.t, w, h, command) for sv, w, h in self.sensors.camera_views()]


def reward_terms(previous_m: float, distance_m: float, outcome: str | None) -> tuple[float, float]:
    """A step's reward as ``(progress toward the goal, m; ±SUCCESS_REWARD at a success / collision end)``."""
    terminal = SUCCESS_REWARD if outcome == "success" else -SUCCESS_REWARD if outcome in ("obstacle", "human") else 0.0
    return previous_m - distance_m, terminal


def register() -> None:
    """Register :data:`ENV_ID` with Gymnasium (idempotent; Gymnasium calls it through its entry points)."""
    _require_gym()
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="song.runtime.env:SongNavEnv")


def make(bench: str, **kwargs: Any):
    """``gym.make(ENV_ID, bench=...)`` with the release's step limit as ``max_episode_steps``."""
    _require_gym()
    register()
    limit = open_benchmark(bench, kwargs.get("version")).params.robot.max_steps
    return gym.make(ENV_ID, bench=bench, max_episode_steps=limit, **kwargs)


def _make_in_worker(bench: str, threads: int, **kwargs: Any):
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    return make(bench, **kwargs)


def make_vector(bench: str, num_envs: int, asynchronous: bool = True, **kwargs: Any):
    """``num_envs`` copies of the env as a Gymnasium vector env (one process each when ``asynchronous``).

    Each copy draws its own episodes from its own seed; the vector env resets a copy when it ends.
    Worker processes are spawned, not forked (numba's OpenMP threads make a forked child abort), and
    each renders with its share of the machine's cores, so the copies do not oversubscribe them.
    """
    _require_gym()
    import os
    from functools import partial

    if asynchronous:
        threads = max(1, (os.cpu_count() or 1) // num_envs)
        return gym.vector.AsyncVectorEnv(
            [partial(_make_in_worker, bench, threads, **kwargs) for _ in range(num_envs)], context="spawn"
        )
    factories = [partial(make, bench, **kwargs) for _ in range(num_envs)]
    return gym.vector.SyncVectorEnv(factories)


class SongVectorEnv(gym.vector.VectorEnv if gym is not None else object):  # type: ignore[misc]
    """``num_envs`` envs in this process, stepped together, their cameras rendered in one call per step.

    A Gymnasium ``VectorEnv`` (autoreset ``NEXT_STEP``, as Gymnasium's own vector envs: the step after an
    episode ends returns the next episode's first observation, with reward 0). Every step renders the
    camera views of all envs through :func:`song.render.render_views` (numba: one projection buffer and
    one parallel loop over every camera's tiles), and each observation equals what that env alone would
    return. Env ``i`` is seeded with ``seed + i``. The envs share one cache of loaded scenes.
    """

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP if gym else None, "render_modes": ["rgb_array"]}

    def __init__(self, bench: str, num_envs: int, **kwargs: Any) -> None:
        _require_gym()
        from gymnasium.vector.utils import batch_space

        if num_envs < 1:
            raise ValueError(f"num_envs must be ≥ 1 (got {num_envs})")
        self.envs = [SongNavEnv(bench, **kwargs) for _ in range(num_envs)]
        self.render_mode = self.envs[0].render_mode
        first = [view for view, _, _ in self.envs[0].sensors.camera_views()]
        for env in self.envs[1:] if first else ():
            for view, _, _ in env.sensors.camera_views():
                view.share_scenes(first[0])
        self.num_envs = num_envs
        self.single_observation_space = self.envs[0].observation_space
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._ended = np.zeros(num_envs, dtype=bool)

    def _observe(self) -> Any:
        from gymnasium.vector.utils import concatenate, create_empty_array

        from song.runtime.vision import render_together

        render_together([job for env in self.envs for job in env._prerender_jobs()])
        observations = [env.runner.observation() for env in self.envs]
        out = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, observations, out)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        """Start an episode in every env (``seed + i`` for env ``i`` when ``seed`` is an int)."""
        seeds = (
            [None if seed is None else seed + i for i in range(self.num_envs)] if not isinstance(seed, list) else seed
        )
        infos: dict[str, Any] = {}
        for i, env in enumerate(self.envs):
            env._start(seeds[i], options)
            infos = self._add_info(infos, env._info(), i)
        self._ended[:] = False
        return self._observe(), infos

    def step(self, actions):
        """Step every env with its row of ``actions``; an env whose episode ended last step starts a new one."""
        rewards = np.zeros(self.num_envs)
        terminations = np.zeros(self.num_envs, dtype=bool)
        truncations = np.zeros(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {}
        for i, env in enumerate(self.envs):
            if self._ended[i]:
                env._start(None, None)
                info = env._info()
            else:
                rewards[i], terminations[i], truncations[i], info = env._advance(actions[i])
            infos = self._add_info(infos, info, i)
        self._ended = terminations | truncations
        return self._observe(), rewards, terminations, truncations, infos

    def render(self) -> tuple | None:
        """Each env's :meth:`SongNavEnv.render` (``render_mode="rgb_array"``), as Gymnasium's vector envs return them."""
        return None if self.render_mode is None else tuple(env.render() for env in self.envs)

    def close_extras(self, **kwargs: Any) -> None:
        """Close every env (Gymnasium's ``close`` calls this once)."""
        for env in self.envs:
            env.close()


if gym is not None:  # so gym.make("song.runtime.env:song/SongNav-v1", ...) works with nothing else imported
    register()
