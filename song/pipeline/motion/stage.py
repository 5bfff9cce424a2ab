"""The motion stage: ``crowd.parquet`` → ``human_amass/traj_{id}/`` per pedestrian."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from song.config import MotionConfig
from song.datasets.run import SceneFolder, read_crowd_table, read_intents, traj_dir_name
from song.errors import SongError
from song.geometry.skeleton import JOINT_NAMES, PARENTS
from song.pipeline.bodies import motion_seed
from song.pipeline.chain import StageContext
from song.pipeline.motion.amass import HAND_SLOTS, pelvis_j0
from song.pipeline.motion.generators import MotionGenerator, ProceduralGait, make_generator
from song.pipeline.motion.io import MOTION_FORMAT, MOTION_VERSION, write_motion
from song.pipeline.motion.postprocess import postprocess
from song.pipeline.motion.postures import STAY_NEAR_M, shelf_track, surface_track
from song.pipeline.motion.quality import motion_quality
from song.pipeline.motion.types import Motion, Trajectory

AMASS_FRAME = (
    "world Z up, metres; root_orient = world-from-SMPL-native (SMPL rest faces +Z, Y up, left +X); pelvis = trans + J0"
)


def read_trajectories(path: str | Path) -> list[Trajectory]:
    """Per-pedestrian trajectories from a ``crowd.parquet`` (sorted by ped_id, then frame).

    Tracks may cover different frame ranges (the motion stage does not need the whole scenario).
    """
    table = read_crowd_table(path)
    col = {name: table.column(name).to_numpy() for name in table.column_names}
    if len(col["ped_id"]) == 0:
        return []
    order = np.lexsort((col["frame"], col["ped_id"]))
    col = {k: v[order] for k, v in col.items()}
    ids, starts = np.unique(col["ped_id"], return_index=True)
    ends = np.append(starts[1:], len(col["ped_id"]))
    out = []
    for ped_id, a, b in zip(ids.tolist(), starts.tolist(), ends.tolist(), strict=True):
        out.append(
            Trajectory(
                ped_id=int(ped_id),
                t=col["t"][a:b].astype(np.float64),
                frame=col["frame"][a:b].astype(np.int32),
                xy=np.stack([col["x"][a:b], col["y"][a:b]], axis=-1).astype(np.float64),
                yaw=col["yaw"][a:b].astype(np.float64),
                speed=col["speed"][a:b].astype(np.float64),
            )
        )
    return out


def _intents_by_id(scene: SceneFolder) -> dict:
    """The scene's intents by pedestrian id (empty when ``intents.json`` is missing or unreadable)."""
    try:
        return read_intents(scene.intents).by_id()
    except SongError:
        return {}


def with_stays(trajectories: list[Trajectory], intents: dict, objects: dict) -> list[Trajectory]:
    """The trajectories with the surfaces their pedestrians rest their hands on and the shelves they browse.

    Stops: the intent's start object (within 0.5 m of its start: the crowd jitters starts) and each
    leg's object (within ``STAY_NEAR_M`` of its goal); see :func:`song.pipeline.motion.postures.stay_track`.
    """
    out = []
    for traj in trajectories:
        intent = intents.get(traj.ped_id)
        if intent is not None:
            stops = [(intent.start_object, intent.start_xy, 0.5)]
            stops += [(leg.goal_object, leg.goal_xy, STAY_NEAR_M) for leg in intent.route()]
            traj = replace(
                traj,
                surface=surface_track(traj.xy, traj.speed, traj.fps, stops, objects),
                shelf=shelf_track(traj.xy, traj.speed, traj.fps, stops, objects),
            )
        out.append(traj)
    return out


def _meta(motion: Motion, traj: Trajectory, alignment: dict, quality: dict, generator: dict) -> dict[str, Any]:
    return {
        "format": MOTION_FORMAT,
        "version": MOTION_VERSION,
        "ped_id": int(traj.ped_id),
        "height_m": round(float(motion.height_m), 6),
        "fps": traj.fps,
        "n_frames": motion.n_frames,
        "skeleton": {
            "joint_names": list(JOINT_NAMES),
            "parents": PARENTS.tolist(),
            "rest_joints": np.round(motion.rest_joints, 6).tolist(),
            "frame": "body x forward, y left, z up; T-pose; feet on z = 0",
        },
        "generator": generator,
        "alignment": alignment,
        "quality": quality,
        "amass": {
            "layout": "SMPL-H poses (T, 156) = root 3 + 21 body joints 63 + 30 hand joints 90; SMPL-X spellings too",
            "frame": AMASS_FRAME,
            "J0": np.round(pelvis_j0(), 6).tolist(),
            "J0_source": "SMPL neutral model, zero betas (pelvis = trans + J0; another model: trans += J0 - J0')",
            "hand_joints": {str(k): v for k, v in HAND_SLOTS.items()},
            "betas": "16 zeros (shape given by rest_joints / height_m)",
        },
    }


def synthesize_motions(
    trajectories: list[Trajectory],
    activities: list[str],
    seeds: list[int],
    cfg: MotionConfig,
    generator: MotionGenerator | None = None,
    fallback_reason: str = "",
) -> list[tuple[Motion, dict[str, Any]]]:
    """Generate, post-process and measure every pedestrian; returns ``(motion, meta)`` pairs."""
    if generator is None:
        generator, fallback_reason = make_generator(cfg)
    try:
        motions = generator.generate(trajectories, activities, seeds)
    except Exception as exc:  # a model failure falls back to the procedural gait, recorded
        if isinstance(generator, ProceduralGait) or cfg.generator == "kimodo":
            raise
        fallback_reason = f"{generator.name} failed: {type(exc).__name__}: {exc}"
        motions = ProceduralGait(cfg).generate(trajectories, activities, seeds)
    out = []
    for motion, traj in zip(motions, trajectories, strict=True):
        final, alignment = postprocess(
            motion,
            traj,
            smoothing_sigma_frames=cfg.smoothing_sigma_frames,
            contact_height_m=cfg.contact_height_m,
            contact_speed_mps=cfg.contact_speed_mps,
            blend_frames=cfg.lock_blend_frames,
        )
        joints = final.joints
        quality = motion_quality(
            joints,
            final.local_quats,
            final.rest_joints,
            final.contacts,
            final.t,
            traj.xy,
            traj.speed,
            motion.info.get("walk_ratio_m_s", cfg.walk_ratio_m_s),  # the pedestrian's own walk ratio
            cfg.min_cadence_spm,
        )
        info = dict(motion.info)
        info.update({"requested": cfg.generator, "fallback": bool(fallback_reason), "fallback_reason": fallback_reason})
        out.append((final, _meta(final, traj, alignment, quality, info)))
    return out


def run_motion(ctx: StageContext) -> list[str]:
    """Stage entry: one folder of motion files per pedestrian of ``crowd.parquet``."""
    cfg = ctx.config.motion
    scene = SceneFolder(ctx.scene_dir)
    trajectories = read_trajectories(scene.crowd)
    ids = [traj.ped_id for traj in trajectories]
    seeds = [motion_seed(ctx.config, ctx.scene_id, ped_id) for ped_id in ids]
    intents = _intents_by_id(scene)
    trajectories = with_stays(trajectories, intents, ctx.scene.semantic_map.object_by_id())
    activities = [intents[i].activity if i in intents else "" for i in ids]
    results = synthesize_motions(trajectories, activities, seeds, cfg)
    keep = {traj_dir_name(i) for i in ids}
    if scene.amass_dir.exists():
        for stale in scene.amass_dir.glob("traj_*"):
            if stale.is_dir() and stale.name not in keep:
                shutil.rmtree(stale)
    written: list[str] = []
    for (motion, meta), traj in zip(results, trajectories, strict=True):
        for path in write_motion(scene.traj_dir(traj.ped_id), motion, meta, traj.fps):
            written.append(path.relative_to(ctx.scene_dir).as_posix())
    return written
