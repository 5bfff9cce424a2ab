"""The intents stage: propose routines (LLM or offline), filter them into executable intents."""

from __future__ import annotations

import hashlib
import json
import os
from collections import Counter
from pathlib import Path

import numpy as np

from song import plugins
from song.config import SongConfig
from song.datasets.run import RunFolder, SceneFolder
from song.datasets.run.intents import Intent, IntentSet, Provenance, RejectedIntent
from song.datasets.run.layout import INTENTS_FILE
from song.datasets.scenes import ScenePackage
from song.errors import MissingDependencyError
from song.pipeline.chain import StageContext, StageOutput
from song.pipeline.intents.groups import form_groups
from song.pipeline.intents.llm import GeminiClient, LLMError, OpenAICompatibleClient, scrub, structured_call
from song.pipeline.intents.navigation import Walkable, snap_points, walkable
from song.pipeline.intents.offline import ROUTE_REPEATS, OfflineIntentModel
from song.pipeline.intents.schemas import RoutineSelection, SceneDescription, load_prompt
from song.util import write_json_atomic

MAX_SOURCE_OBJECTS = 16
MAX_CANDIDATES = 40  # candidate pairs listed in prompt B (MAX_SOURCE_OBJECTS: objects geodesics start from)


def pedestrian_count(area_m2: float, config: SongConfig) -> int:
    """Pedestrians for a scene: density × navigable area, bounded."""
    cfg = config.intents
    return int(np.clip(round(cfg.density_per_m2 * area_m2), cfg.min_pedestrians, cfg.max_pedestrians))


def _facing(candidates: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """The candidate point closest to ``towards`` (the side of the object facing the other one)."""
    return candidates[int(np.argmin(np.linalg.norm(candidates - towards, axis=1)))]


def _free_spot(candidates: np.ndarray, preferred: np.ndarray, taken: list[np.ndarray], separation: float):
    """``preferred`` itself if it is ``separation`` from every taken spot, else the nearest candidate that is; None if none."""
    if not taken:
        return preferred
    taken_xy = np.asarray(taken)
    if np.linalg.norm(taken_xy - preferred, axis=1).min() >= separation:
        return preferred
    clear = np.linalg.norm(candidates[:, None] - taken_xy[None], axis=-1).min(axis=1) >= separation
    if not clear.any():
        return None
    ok = candidates[clear]
    return ok[int(np.argmin(np.linalg.norm(ok - preferred, axis=1)))]


def _pair_geodesics(
    walk: Walkable, snaps: dict[str, np.ndarray], rng: np.random.Generator
) -> dict[tuple[str, str], float]:
    ids = sorted(snaps)
    if len(ids) < 2:
        return {}
    sources = (
        ids if len(ids) <= MAX_SOURCE_OBJECTS else sorted(rng.choice(ids, MAX_SOURCE_OBJECTS, replace=False).tolist())
    )
    out = {}
    rows, _ = walk.geodesics_from(np.array([snaps[a][0] for a in sources]))
    for a, dist in zip(sources, rows, strict=True):
        for b in ids:
            if b != a:
                length = walk.geodesic(dist, snaps[b][0])
                if np.isfinite(length):
                    out[(a, b)] = length
    return out


def _proposal_ends(proposals, objects: dict, snaps: dict[str, np.ndarray], walk: Walkable) -> tuple[dict, dict]:
    """Facing start/goal points of every proposal between reachable objects, and geodesic rows from the starts.

    The rows come from one search for all the starts.
    """
    ends = {}
    for start_id, goal_id, _ in proposals:
        if len(snaps.get(start_id, ())) and len(snaps.get(goal_id, ())) and start_id in objects and goal_id in objects:
            start = _facing(snaps[start_id], np.mean(objects[goal_id].footprint, axis=0))
            ends[(start_id, goal_id)] = (start, _facing(snaps[goal_id], start))
    keys = sorted(ends)
    rows = walk.geodesics_from(np.array([ends[k][0] for k in keys]))[0] if keys else []
    return ends, dict(zip(keys, rows, strict=True))


def _standing_conflict(start: np.ndarray, goal: np.ndarray, kept: list[Intent], separation: float):
    """``(reason, detail)`` when a new start or goal stands too close to a kept one's, else None.

    People stand at their start before leaving and at their goal after arriving: keep those apart.
    """
    if any(np.linalg.norm(start - np.asarray(k.start_xy)) < separation for k in kept):
        return "spawn_conflict", "another start within 0.8 m"
    standing = [np.asarray(k.goal_xy) for k in kept] + [np.asarray(k.start_xy) for k in kept]
    if any(np.linalg.norm(goal - p) < separation for p in standing) or any(
        np.linalg.norm(start - np.asarray(k.goal_xy)) < separation for k in kept
    ):
        return "standing_conflict", "start/goal within 0.8 m of another's"
    return None


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
    routes: list[tuple[str, str]] = []
    ends, distance_rows = _proposal_ends(proposals, objects, snaps, walk)
    for start_id, goal_id, activity in proposals:
        base = {"activity": activity, "start_object": start_id, "goal_object": goal_id}
        if start_id not in objects or goal_id not in objects:
            missing = start_id if start_id not in objects else goal_id
            rejected.append(RejectedIntent(**base, reason="unknown_object", detail=f"no object '{missing}'"))
            continue
        if len(snaps.get(start_id, ())) == 0 or len(snaps.get(goal_id, ())) == 0:
            rejected.append(RejectedIntent(**base, reason="unreachable", detail="no free standing point next to it"))
            continue
        if routes.count((start_id, goal_id)) >= ROUTE_REPEATS:
            rejected.append(
                RejectedIntent(**base, reason="duplicate", detail=f"{ROUTE_REPEATS} people walk it already")
            )
            continue
        start, goal = ends[(start_id, goal_id)]
        row = distance_rows[(start_id, goal_id)]
        # several people may start or end at one object: the nearest free spot around it to the facing one
        taken = [np.asarray(k.start_xy) for k in kept] + [np.asarray(k.goal_xy) for k in kept]
        free_start = _free_spot(snaps[start_id], start, taken, cfg.min_spawn_separation_m)
        if free_start is not None and free_start is not start:
            start, row = free_start, walk.geodesics_from(free_start[None])[0][0]
        free_goal = _free_spot(snaps[goal_id], goal, [*taken, start], cfg.min_spawn_separation_m)
        goal = goal if free_goal is None else free_goal
        length = walk.geodesic(row, goal)
        if not np.isfinite(length):
            rejected.append(RejectedIntent(**base, reason="unreachable", detail="goal not connected to start"))
            continue
        if length < cfg.min_path_m or length > cfg.max_path_m:
            reason = "too_short" if length < cfg.min_path_m else "too_long"
            rejected.append(RejectedIntent(**base, reason=reason, detail=f"{length:.2f} m"))
            continue
        conflict = _standing_conflict(start, goal, kept, cfg.min_spawn_separation_m)
        if conflict:
            rejected.append(RejectedIntent(**base, reason=conflict[0], detail=conflict[1]))
            continue
        if len(kept) >= limit:
            rejected.append(RejectedIntent(**base, reason="over_limit"))
            continue
        routes.append((start_id, goal_id))
        kept.append(
            Intent(
                id=len(kept),
                activity=activity,
                start_object=start_id,
                goal_object=goal_id,
                start_xy=(round(float(start[0]), 4), round(float(start[1]), 4)),
                goal_xy=(round(float(goal[0]), 4), round(float(goal[1]), 4)),
                speed=round(draw_speed(cfg, rng), 4),
                depart_time=round(float(rng.uniform(-cfg.lead_in_s, cfg.max_depart_s)), 4),
                geodesic_m=round(length, 3),
                provenance=provenance,
            )
        )
    return kept, rejected


HUMAN_SPEED_MPS, HUMAN_SPEED_SD, HUMAN_SPEED_RANGE = 1.3, 0.2, (0.8, 1.8)  # free walking of adults indoors


def draw_speed(cfg, rng: np.random.Generator) -> float:
    """A preferred walking speed by ``intents.speed_profile``.

    ``paper``: uniform in [speed_min, speed_max] (0.5–1.0 m/s, the paper's benchmark); ``human``:
    normal around 1.3 m/s with sd 0.2, clipped to 0.8–1.8 m/s (adults' comfortable walking speed,
    Bohannon 1997; Weidmann 1993's mean free speed 1.34 m/s).
    """
    if cfg.speed_profile == "human":
        return float(np.clip(rng.normal(HUMAN_SPEED_MPS, HUMAN_SPEED_SD), *HUMAN_SPEED_RANGE))
    return float(rng.uniform(cfg.speed_min_mps, cfg.speed_max_mps))


# dwell at an object, s, by what the object is (first matching keyword): waiting at a counter, working
# at a desk, browsing a shelf, using a machine; default a short stop
DWELL_S = (
    (("counter", "reception", "checkout", "desk", "help", "bar", "pharmacy"), (3.0, 8.0)),
    (("workstation", "table", "computer", "bed", "sofa", "chair", "seat"), (5.0, 15.0)),
    (("shelf", "shelving", "book", "stack", "rack", "display"), (3.0, 10.0)),
    (("printer", "machine", "fridge", "elevator", "sink", "coffee"), (3.0, 6.0)),
)
DEFAULT_DWELL_S = (3.0, 6.0)


def dwell_time(obj, rng: np.random.Generator) -> float:
    """How long a pedestrian stays at ``obj`` before walking on, s (by the object's label and category)."""
    text = f"{obj.label} {obj.category}".lower()
    low, high = next((span for keys, span in DWELL_S if any(k in text for k in keys)), DEFAULT_DWELL_S)
    return float(rng.uniform(low, high))


def extend_routines(
    kept: list[Intent], package: ScenePackage, walk: Walkable, snaps: dict[str, np.ndarray], config: SongConfig, rng
) -> list[Intent]:
    """Chain more legs after each intent's first, until ``scenario_s`` is covered or ``max_legs`` reached.

    From where it stands, a pedestrian walks on to another reachable object (not the one it just came
    from) at a geodesic distance within [min_path, max_path], preferring objects related to the current
    one and longer walks, at a standing spot no other pedestrian uses (the free one nearest to the side
    facing it, :func:`_free_spot`); it dwells at each object
    (:func:`dwell_time`). The offline model's activity phrases name the later legs.
    """
    from song.datasets.run.intents import Leg
    from song.pipeline.intents.offline import activity_phrase, relatedness

    cfg = config.intents
    objects = package.semantic_map.object_by_id()
    taken = [np.asarray(k.start_xy) for k in kept] + [np.asarray(k.goal_xy) for k in kept]
    routines = []
    for intent in kept:
        legs = [
            Leg(activity=intent.activity, goal_object=intent.goal_object, goal_xy=intent.goal_xy,
                geodesic_m=intent.geodesic_m, dwell_s=0.0)
        ]  # fmt: skip
        clock = intent.depart_time + intent.geodesic_m / intent.speed
        previous, here = intent.start_object, np.asarray(intent.goal_xy)
        while len(legs) < cfg.max_legs and clock < cfg.scenario_s:
            dwell = dwell_time(objects[legs[-1].goal_object], rng)
            dist = walk.geodesics_from(here[None])[0][0]
            options, weights, ends = [], [], []
            for oid, pts in snaps.items():
                if oid in (legs[-1].goal_object, previous):
                    continue
                end = _free_spot(pts, _facing(pts, here), taken, cfg.min_spawn_separation_m)
                if end is None:  # every spot around it is someone's
                    continue
                length = walk.geodesic(dist, end)
                fits = clock + dwell + length / intent.speed <= cfg.scenario_s  # the routine ends in the scenario
                if fits and cfg.min_path_m <= length <= cfg.max_path_m:
                    options.append((oid, length))
                    ends.append(end)
                    weights.append((1.0 + 2.0 * relatedness(objects[legs[-1].goal_object], objects[oid])) * length**2)
            if not options:
                break
            pick = int(rng.choice(len(options), p=np.asarray(weights) / np.sum(weights)))
            oid, length = options[pick]
            legs[-1] = legs[-1].model_copy(update={"dwell_s": round(dwell, 3)})
            end = ends[pick]
            legs.append(
                Leg(activity=activity_phrase(package.semantic_map.venue_type, objects[legs[-1].goal_object],
                                             objects[oid], rng),
                    goal_object=oid, goal_xy=(round(float(end[0]), 4), round(float(end[1]), 4)),
                    geodesic_m=round(length, 3))
            )  # fmt: skip
            taken.append(end)
            clock += dwell + length / intent.speed
            previous, here = legs[-2].goal_object, end
        routines.append(intent.model_copy(update={"legs": legs}))
    return routines


def choose_provider(llm: str) -> str:
    """``auto`` → gemini when a Gemini/Google key is set, else offline."""
    if llm != "auto":
        return llm
    return "gemini" if os.environ.get("GOOGLE_API_KEY") or os.environ.get("GEMINI_API_KEY") else "offline"


def _gemini(config: SongConfig) -> GeminiClient:
    cfg = config.intents
    return GeminiClient(cfg.gemini_model, cfg.timeout_s, base_url=os.environ.get("SONG_GEMINI_BASE_URL"))


def _openai(config: SongConfig) -> OpenAICompatibleClient:
    cfg = config.intents
    return OpenAICompatibleClient(cfg.openai_base_url, cfg.openai_model, cfg.timeout_s)


plugins.add("llm", "gemini", _gemini)
plugins.add("llm", "openai", _openai)


def make_client(provider: str, config: SongConfig):
    """The LLM client of ``provider``: an ``llm`` plugin, ``factory(config) -> client``.

    A client has ``provider`` and ``model`` attributes and ``request(prompt, schema) -> str`` (the reply
    text; :class:`~song.pipeline.intents.llm.LLMError` on failure, ``TransientLLMError`` when worth
    retrying, ``LLMRefusal`` for a safety block).
    """
    return plugins.lookup("llm", provider)(config)


def _scene_summary(package: ScenePackage) -> str:
    smap = package.semantic_map
    regions = [{"id": r.id, "type": r.type, "name": r.name} for r in smap.regions]
    objects = [{"id": o.id, "label": o.label, "category": o.category, "region": o.region} for o in smap.objects]
    return json.dumps({"venue_type": smap.venue_type, "regions": regions, "objects": objects}, sort_keys=True)


def llm_proposals(package: ScenePackage, geodesic: dict, n: int, config: SongConfig, client, cache_dir: Path | None):
    """Prompt A (scene description) then prompt B (routine selection) → (proposals, description, prompts' sha256)."""
    cfg = config.intents
    call = {
        "cache_dir": cache_dir,
        "max_retries": cfg.max_retries,
        "backoff_s": cfg.backoff_base_s,
        "max_concurrency": cfg.max_concurrency,
    }
    prompt_a = load_prompt("scene_description").format(scene=_scene_summary(package))
    description = structured_call(client, prompt_a, SceneDescription, **call)
    best = sorted(geodesic.items(), key=lambda item: (-item[1], item[0]))[:MAX_CANDIDATES]
    candidates = "\n".join(f"- {a} -> {b}: {length:.1f} m" for (a, b), length in best)
    prompt = load_prompt("route_selection").format(
        description=description.description, candidates=candidates, count=2 * n, venue=package.semantic_map.venue_type
    )
    selection = structured_call(client, prompt, RoutineSelection, **call)
    digest = hashlib.sha256(f"{prompt_a}\n\n{prompt}".encode()).hexdigest()
    return [(r.start_object, r.goal_object, r.activity) for r in selection.routines], description.description, digest


def generate_intents(
    package: ScenePackage, config: SongConfig, rng: np.random.Generator, cache_dir: Path | None = None
) -> IntentSet:
    """Proposals (LLM or offline) → filtered intents for one scene; an LLM failure falls back to offline."""
    walk = walkable(package, config.crowd.agent_radius_m, config.crowd.contour_error_m)
    regions = {region.id: region.polygon for region in package.semantic_map.regions}
    snaps = {obj.id: snap_points(walk, obj.footprint, regions.get(obj.region)) for obj in package.semantic_map.objects}
    snaps = {k: v for k, v in snaps.items() if len(v)}
    n = pedestrian_count(walk.area_m2, config)
    geodesic = _pair_geodesics(walk, snaps, rng)
    notes = scene_notes(package, walk, snaps, geodesic)
    if notes:  # nothing a pedestrian could do here: record why instead of asking a model
        provenance = Provenance(provider="offline", model=OfflineIntentModel().model)
        return IntentSet(scene_id=package.scene_id, provenance=provenance, intents=[], notes=notes)
    provider = choose_provider(config.intents.llm)
    description, llm_error, kept = "", "", None
    offline = OfflineIntentModel()
    if provider != "offline":
        digest, client = "", None
        try:
            client = make_client(provider, config)
            proposals, description, digest = llm_proposals(package, geodesic, n, config, client, cache_dir)
            provenance = Provenance(provider=provider, model=client.model, prompt_sha256=digest)
            kept, rejected = filter_intents(proposals, package, walk, snaps, config, provenance, rng, n)
            if not kept:  # e.g. every routine names objects the scene does not have: as good as no answer
                reasons = Counter(r.reason for r in rejected)
                detail = ", ".join(f"{reason} {count}" for reason, count in sorted(reasons.items()))
                raise LLMError(f"none of the model's {len(proposals)} routines passed the filters ({detail})")
        except (LLMError, MissingDependencyError) as exc:
            llm_error = scrub(str(exc))
            builtin = {"gemini": config.intents.gemini_model, "openai": config.intents.openai_model}
            model = getattr(client, "model", None) or builtin.get(provider, provider)
            provenance = Provenance(provider=provider, model=model, fallback=True, prompt_sha256=digest)
            kept = None
    else:
        provenance = Provenance(provider="offline", model=offline.model)
    if kept is None:
        proposals = offline.propose(package.semantic_map, geodesic, 2 * n, rng)
        kept, rejected = filter_intents(proposals, package, walk, snaps, config, provenance, rng, n)
    kept = extend_routines(kept, package, walk, snaps, config, rng)
    kept = form_groups(kept, walk, config.intents.group_share, config.intents.min_spawn_separation_m, rng)
    return IntentSet(
        scene_id=package.scene_id,
        provenance=provenance,
        description=description,
        intents=kept,
        rejected=rejected,
        llm_error=llm_error,
        notes=[] if kept else ["no proposed routine passed the filters (see rejected)"],
    )


def scene_notes(package: ScenePackage, walk: Walkable, snaps: dict, geodesic: dict) -> list[str]:
    """Why a scene cannot hold any routine (empty when it can): the first missing ingredient."""
    if walk.area_m2 <= 0.0:
        return [f"no walkable area for a {walk.radius:.2f} m body"]
    if len(package.semantic_map.objects) < 2:
        return [f"{len(package.semantic_map.objects)} object(s): a routine needs a start and a goal object"]
    if len(snaps) < 2:
        return [f"{len(snaps)} object(s) with a free standing point next to them (need 2)"]
    if not geodesic:
        return ["no two objects are connected by walkable space"]
    return []


def run_intents(ctx: StageContext) -> StageOutput:
    """Stage entry: write ``intents.json``; totals count intents and LLM fallbacks (for the run summary)."""
    run = RunFolder(ctx.run_dir)
    intents = generate_intents(ctx.scene, ctx.config, ctx.rng("intents"), cache_dir=run.llm_cache)
    write_json_atomic(SceneFolder(ctx.scene_dir).intents, intents.model_dump(mode="json"))
    return StageOutput([INTENTS_FILE], {"llm_fallbacks": int(intents.provenance.fallback)})
