"""Motion stage: planned root tracks → full-body motion on the 24-joint skeleton.

Then trajectory-consistency post-processing and AMASS export (``human_amass/traj_{id}/``).
"""

from song.pipeline.chain import Stage, register_stage
from song.pipeline.motion.generators import MotionGenerator, ProceduralGait, make_generator
from song.pipeline.motion.io import LoadedMotion, load_motion
from song.pipeline.motion.stage import read_trajectories, run_motion, synthesize_motions
from song.pipeline.motion.types import Motion, Trajectory

register_stage(Stage(name="motion", run=run_motion, depends=("crowd",), reads=("motion",)))

__all__ = [
    "LoadedMotion",
    "Motion",
    "MotionGenerator",
    "ProceduralGait",
    "Trajectory",
    "load_motion",
    "make_generator",
    "read_trajectories",
    "run_motion",
    "synthesize_motions",
]
