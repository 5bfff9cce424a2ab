"""Intents stage (DESIGN §5.1): semantic pedestrian routines for a scene."""

from song.pipeline.chain import Stage, register_stage
from song.pipeline.intents.model import Intent, IntentSet, load_intents
from song.pipeline.intents.stage import generate_intents, run_intents

register_stage(Stage(name="intents", run=run_intents, depends=(), config_section="intents"))

__all__ = ["Intent", "IntentSet", "generate_intents", "load_intents", "run_intents"]
