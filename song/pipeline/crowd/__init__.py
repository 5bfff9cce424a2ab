"""Crowd stage: navmesh + ORCA crowd simulation with DetourCrowd's structure at 30 FPS."""

from song.pipeline.chain import Stage, register_stage
from song.pipeline.crowd.navmesh import load_navmesh
from song.pipeline.crowd.stage import run_crowd

# the body radii come from the avatars binding will pick and the heights motion will draw (song.pipeline.bodies)
register_stage(
    Stage(
        name="crowd",
        run=run_crowd,
        depends=("intents",),
        reads=("crowd", "binding", "motion.height_min_m", "motion.height_max_m"),
    )
)

__all__ = ["load_navmesh", "run_crowd"]
