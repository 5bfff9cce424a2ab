"""Motion generators.

The :class:`MotionGenerator` interface, the always-available :class:`ProceduralGait`, and the choice
between it and Kimodo.

``generate(trajectories, activities, seeds) -> list[Motion]`` is batched over pedestrians: one
motion per trajectory, in order, each at the generator's own time stamps (post-processing resamples
onto the plan). Seeds are per pedestrian; the same seed gives the same motion.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from song import plugins
from song.config import MotionConfig
from song.errors import StageError
from song.pipeline.motion.gait import generate_gait, style_for
from song.pipeline.motion.types import Motion, Trajectory


class MotionGenerator(Protocol):
    """Anything that turns planned root tracks into skeletal motions."""

    name: str

    def generate(
        self, trajectories: Sequence[Trajectory], activities: Sequence[str], seeds: Sequence[int]
    ) -> list[Motion]:
        """One :class:`Motion` per trajectory (same order)."""
        ...


class ProceduralGait:
    """Walk-ratio procedural gait (:mod:`song.pipeline.motion.gait`); needs nothing but numpy."""

    name = "procedural"

    def __init__(self, cfg: MotionConfig | None = None) -> None:
        self.cfg = cfg or MotionConfig()

    def generate(
        self, trajectories: Sequence[Trajectory], activities: Sequence[str], seeds: Sequence[int]
    ) -> list[Motion]:
        """One procedural motion per trajectory, each with its own style drawn from its seed."""
        if not (len(trajectories) == len(activities) == len(seeds)):
            raise ValueError("trajectories, activities and seeds must have the same length")
        motions = []
        for traj, activity, seed in zip(trajectories, activities, seeds, strict=True):
            style = style_for(int(seed), self.cfg)
            motion = generate_gait(traj, style, self.cfg.min_cadence_spm)
            motion.info = {
                "name": "procedural",
                "seed": int(seed),
                "activity": activity,
                "walk_ratio_m_s": round(style.walk_ratio, 6),
                "style": style.to_json(),
            }
            motions.append(motion)
        return motions


def make_generator(cfg: MotionConfig) -> tuple[MotionGenerator, str]:
    """The generator the config asks for, and the fallback reason ("" when none).

    ``auto`` uses Kimodo when ``kimodo`` imports and its weights are present locally, otherwise the
    procedural gait (the reason is recorded); ``kimodo`` raises :class:`StageError` when unavailable.
    Any other name is a ``motion_generator`` plugin (:mod:`song.plugins`), built as ``Generator(cfg)``.
    """
    if cfg.generator not in ("auto", "kimodo"):
        return plugins.lookup("motion_generator", cfg.generator)(cfg), ""
    from song.pipeline.motion.kimodo import KimodoGenerator, kimodo_availability

    reason = kimodo_availability(cfg)
    if not reason:
        return KimodoGenerator(cfg), ""
    if cfg.generator == "kimodo":
        raise StageError(f"motion.generator = kimodo but Kimodo is unavailable: {reason}")
    return ProceduralGait(cfg), reason


def _kimodo_generator(cfg: MotionConfig) -> MotionGenerator:
    generator, _ = make_generator(cfg.model_copy(update={"generator": "kimodo"}))
    return generator


plugins.add("motion_generator", "procedural", ProceduralGait)
plugins.add("motion_generator", "kimodo", _kimodo_generator)
