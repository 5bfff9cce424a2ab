"""Binding stage: avatar identities and linear-blend-skinning caches per pedestrian."""

from song.pipeline.binding.stage import bind_motion, run_binding
from song.pipeline.chain import Stage, register_stage

register_stage(Stage(name="binding", run=run_binding, depends=("motion",), reads=("binding", "crowd.fps")))

__all__ = ["bind_motion", "run_binding"]
