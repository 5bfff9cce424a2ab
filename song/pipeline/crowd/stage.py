"""The crowd stage: intents → joint 30 FPS trajectories (``crowd.parquet``) + per-pedestrian status.

The files' contracts live in :mod:`song.datasets.run` (the crowd table's columns, the status record).
"""

from __future__ import annotations

import numpy as np

from song.datasets.run import SceneFolder, crowd_table, read_intents, write_crowd, write_crowd_status
from song.datasets.run.layout import CROWD_FILE, CROWD_STATUS_FILE, NAVMESH_FILE
from song.pipeline.bodies import body_radii
from song.pipeline.chain import StageContext, StageOutput
from song.pipeline.crowd.avoidance import make_avoidance
from song.pipeline.crowd.navmesh import save_navmesh, scene_navmesh
from song.pipeline.crowd.simulate import CrowdPlan, plan_crowd


def plan_table(plan: CrowdPlan):
    """The crowd table (:func:`song.datasets.run.crowd_table`) of a plan."""
    return crowd_table(plan.ped_ids, plan.xy, plan.yaw, plan.speed, plan.fps)


def run_crowd(ctx: StageContext) -> StageOutput:
    """Stage entry: build the navmesh, plan the crowd on it, write its files."""
    scene = SceneFolder(ctx.scene_dir)
    intents = read_intents(scene.intents)
    cfg = ctx.config.crowd
    mesh = scene_navmesh(ctx.scene, cfg.agent_radius_m, cfg.contour_error_m)
    outlines = {obj.id: np.asarray(obj.footprint, dtype=np.float64) for obj in ctx.scene.semantic_map.objects}
    radii = None
    if cfg.radius_from_avatar and intents.intents:
        radii = body_radii(ctx.config, ctx.scene_id, [intent.id for intent in intents.intents])
    avoid = make_avoidance(mesh, cfg)
    plan = plan_crowd(intents.intents, mesh, avoid, cfg, ctx.rng("crowd"), outlines=outlines, radii=radii)
    table = plan_table(plan)
    save_navmesh(scene.navmesh, mesh)
    write_crowd(scene.crowd, table)
    write_crowd_status(scene.crowd_status, plan.status)
    totals = {"pedestrians": len(plan.ped_ids), "pedestrian_frames": table.num_rows}
    return StageOutput([CROWD_FILE, CROWD_STATUS_FILE, NAVMESH_FILE], totals)
