"""The intents stage: propose routines (LLM or offline), filter them into executable intents."""

from __future__ import annotations

import numpy as np

from song.config import SongConfig
from song.datasets.scenes import ScenePackage
from song.pipeline.chain import StageContext
from song.pipeline.intents.model import INTENTS_FILE, Intent, IntentSet, Provenance, RejectedIntent
from song.pipeline.intents.navigation import Walkable, snap_points, walkable
from song.pipeline.intents.offline import OfflineIntentModel
from song.util import write_json_atomic

MAX_SOURCE_OBJECTS = 16  # objects from which geodesics are estimated for pair proposals


def pedestrian_count(area_m2: float, config: SongConfig) -> int:
    """Pedestrians for a scene: density × navigable area, bounded."""
    cfg = config.intents
    return int(np.clip(round(cfg.density_per_m2 * area_m2), cfg.min_pedestrians, cfg.max_pedestrians))


def _facing(candidates: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """The candidate point closest to ``towards`` (the side of the object facing the other one)."""
    return candidates[int(np.argmin(np.linalg.norm(candidates - towards, axis=1)))]


def _pair_geodesics(
    walk: Walkable, snaps: dict[str, np.ndarray], rng: np.random.Generator
) -> dict[tuple[str, str], float]:
    ids = sorted(snaps)
    sources = (
        ids if len(ids) <= MAX_SOURCE_OBJECTS else sorted(rng.choice(ids, MAX_SOURCE_OBJECTS, replace=False).tolist())
    )
    out = {}
    for a in sources:
        dist, _ = walk.geodesic_from(snaps[a][0])
        for b in ids:
            if b != a:
                length = walk.geodesic(dist, snaps[b][0])
                if np.isfinite(length):
                    out[(a, b)] = length
    return out


def filter_intents(
    proposals: list[tuple[str, str, str]],
    package: ScenePackage,
    walk: Walkable,
    snaps: dict[str, np.ndarray],
    config: SongConfig,
    provenance: Provenance,
    rng: np.random.Generator,
    limit: int,
) -> tuple[list[Intent], list[RejectedIntent]]:
    """Turn proposals into executable intents; every rejection carries a reason code."""
    cfg = config.intents
    objects = package.semantic_map.object_by_id()
    kept: list[Intent] = []
    rejected: list[RejectedIntent] = []
    routes = set()
    for start_id, goal_id, activity in proposals:
        base = {"activity": activity, "start_object": start_id, "goal_object": goal_id}
        if start_id not in objects or goal_id not in objects:
            missing = start_id if start_id not in objects else goal_id
            rejected.append(RejectedIntent(**base, reason="unknown_object", detail=f"no object '{missing}'"))
            continue
        if len(snaps.get(start_id, ())) == 0 or len(snaps.get(goal_id, ())) == 0:
            rejected.append(RejectedIntent(**base, reason="unreachable", detail="no free standing point next to it"))
            continue
        if (start_id, goal_id) in routes:
            rejected.append(RejectedIntent(**base, reason="duplicate"))
            continue
        goal_centre = np.mean(objects[goal_id].footprint, axis=0)
        start = _facing(snaps[start_id], goal_centre)
        goal = _facing(snaps[goal_id], start)
        dist, _ = walk.geodesic_from(start)
        length = walk.geodesic(dist, goal)
        if not np.isfinite(length):
            rejected.append(RejectedIntent(**base, reason="unreachable", detail="goal not connected to start"))
            continue
        if length < cfg.min_path_m or length > cfg.max_path_m:
            reason = "too_short" if length < cfg.min_path_m else "too_long"
            rejected.append(RejectedIntent(**base, reason=reason, detail=f"{length:.2f} m"))
            continue
        if any(np.linalg.norm(start - np.asarray(k.start_xy)) < cfg.min_spawn_separation_m for k in kept):
            rejected.append(RejectedIntent(**base, reason="spawn_conflict", detail="another start within 0.8 m"))
            continue
        # people stand at their start before leaving and at their goal after arriving: keep those apart
        standing = [np.asarray(k.goal_xy) for k in kept] + [np.asarray(k.start_xy) for k in kept]
        if any(np.linalg.norm(goal - p) < cfg.min_spawn_separation_m for p in standing) or any(
            np.linalg.norm(start - np.asarray(k.goal_xy)) < cfg.min_spawn_separation_m for k in kept
        ):
            rejected.append(
                RejectedIntent(**base, reason="standing_conflict", detail="start/goal within 0.8 m of another's")
            )
            continue
        if len(kept) >= limit:
            rejected.append(RejectedIntent(**base, reason="over_limit"))
            continue
        routes.add((start_id, goal_id))
        kept.append(
            Intent(
                id=len(kept),
                activity=activity,
                start_object=start_id,
                goal_object=goal_id,
                start_xy=(round(float(start[0]), 4), round(float(start[1]), 4)),
                goal_xy=(round(float(goal[0]), 4), round(float(goal[1]), 4)),
                speed=round(float(rng.uniform(cfg.speed_min_mps, cfg.speed_max_mps)), 4),
                depart_time=round(float(rng.uniform(0.0, cfg.max_depart_s)), 4),
                geodesic_m=round(length, 3),
                provenance=provenance,
            )
        )
    return kept, rejected


def generate_intents(package: ScenePackage, config: SongConfig, rng: np.random.Generator) -> IntentSet:
    """Offline proposals → filtered intents for one scene."""
    walk = walkable(package, config.crowd.agent_radius_m)
    regions = {region.id: region.polygon for region in package.semantic_map.regions}
    snaps = {obj.id: snap_points(walk, obj.footprint, regions.get(obj.region)) for obj in package.semantic_map.objects}
    snaps = {k: v for k, v in snaps.items() if len(v)}
    n = pedestrian_count(walk.area_m2, config)
    model = OfflineIntentModel()
    proposals = model.propose(package.semantic_map, _pair_geodesics(walk, snaps, rng), 2 * n, rng)
    provenance = Provenance(provider="offline", model=model.model)
    kept, rejected = filter_intents(proposals, package, walk, snaps, config, provenance, rng, n)
    return IntentSet(scene_id=package.scene_id, provenance=provenance, intents=kept, rejected=rejected)


def run_intents(ctx: StageContext) -> list[str]:
    """Stage entry: write ``intents.json``."""
    intents = generate_intents(ctx.scene, ctx.config, ctx.rng("intents"))
    write_json_atomic(ctx.scene_dir / INTENTS_FILE, intents.model_dump(mode="json"))
    return [INTENTS_FILE]
