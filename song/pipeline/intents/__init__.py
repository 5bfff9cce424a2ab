"""Intents stage: semantic pedestrian routines for a scene."""

from song.pipeline.chain import Stage, register_stage
from song.pipeline.intents.stage import generate_intents, run_intents

# the walkable grid follows the crowd's body radius and navmesh simplification (a kept goal must be reachable)
register_stage(
    Stage(
        name="intents",
        run=run_intents,
        depends=(),
        reads=("intents", "crowd.agent_radius_m", "crowd.contour_error_m"),
    )
)

__all__ = ["generate_intents", "run_intents"]
