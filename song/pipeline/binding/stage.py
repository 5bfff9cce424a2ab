"""The binding stage: motion → avatar identity + LBS cache per pedestrian.

Per scene: every pedestrian with a motion (``human_amass/traj_{id}/motion.npz``) gets an identity from
the pool, :func:`song.pipeline.bodies.identity_picks` over the scene's pedestrians in id order (a fresh
permutation of the pool each time it runs out, so no identity repeats within a scene while the pool
allows; the crowd stage asked the same function for the body radii), uniformly scaled to the motion's
body height (the root alignment: ``diag(s, s, s, 1)``, recorded). Outputs under ``binding/``:
``traj_{id}.npz`` (compact cache), ``traj_{id}.materialized.npz`` when ``binding.materialize``, and
``bindings.json`` (contract in docs/contracts.md).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from song.datasets.avatars.asset import AvatarAsset, load_avatar
from song.datasets.avatars.cache import MotionCache, write_compact_cache, write_materialized_cache
from song.datasets.run import BindingRecord, Bindings, SceneFolder, read_intents, write_bindings
from song.datasets.run.layout import BINDINGS_FILE, CACHE_FILE, MATERIALIZED_FILE, MOTION_META_FILE, traj_ped_id
from song.errors import FormatError, SongError
from song.pipeline.binding.pool import ensure_pool
from song.pipeline.bodies import identity_picks
from song.pipeline.chain import StageContext
from song.pipeline.motion.io import LoadedMotion, load_motion


def _scene_ped_ids(scene: SceneFolder, motion_ids: list[int]) -> list[int]:
    """Every pedestrian of the scene: its intents' ids (those the crowd could not start included) and the motions'."""
    try:
        intent_ids = [intent.id for intent in read_intents(scene.intents).intents]
    except (OSError, SongError):
        intent_ids = []
    return sorted(set(intent_ids) | set(motion_ids))


def _motions(scene: SceneFolder) -> list[tuple[int, LoadedMotion]]:
    """(pedestrian id, motion) per motion folder; the id is the folder's (``traj_<id>``), checked against its meta."""
    out = []
    for folder in scene.motion_dirs():
        ped_id, motion = traj_ped_id(folder), load_motion(folder)
        if int(motion.meta.get("ped_id", ped_id)) != ped_id:
            raise FormatError(
                folder / MOTION_META_FILE, "ped_id", f"is {motion.meta['ped_id']}, the folder's is {ped_id}"
            )
        out.append((ped_id, motion))
    return out


@dataclass(frozen=True)
class _Identity:
    """What binding reads of a pool avatar: its id, rest height, rest skeleton and content hash."""

    avatar_id: str
    height_m: float
    rest_joints: np.ndarray
    sha256: str


_VERIFIED: dict[tuple[str, int, int], _Identity] = {}


def _verified_identity(path: Path) -> _Identity:
    """A pool avatar's identity, read and its content hash checked once per process.

    Keyed by the file's resolved path, size and modification time: a worker binding hundreds of scenes
    reads each of the pool's identities once, and an asset rewritten meanwhile is read (and checked) again.
    """
    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if key not in _VERIFIED:
        asset = load_avatar(path)
        _VERIFIED[key] = _Identity(asset.avatar_id, asset.height_m, asset.rest_joints, asset.meta.get("sha256", ""))
    return _VERIFIED[key]


def _motion_cache(identity: _Identity, motion: LoadedMotion, fps: float, ped_id: int | None) -> MotionCache:
    scale = float(motion.height_m) / identity.height_m
    rest = (identity.rest_joints * scale).astype(np.float32)  # exactly AvatarAsset.scaled's rest skeleton
    alignment = np.diag([scale, scale, scale, 1.0])
    meta: dict[str, Any] = {
        "ped_id": int(motion.meta.get("ped_id", -1)) if ped_id is None else int(ped_id),
        "avatar_id": identity.avatar_id,
        "avatar_sha256": identity.sha256,
        "height_m": round(float(motion.height_m), 6),
        "scale": scale,
        "alignment": alignment.ravel().tolist(),
        "fps": fps,
        "frame0": int(motion.frame[0]),
        "skeleton_mismatch_m": round(float(np.abs(rest - motion.rest_joints).max()), 6),
    }
    return MotionCache(
        motion.root_pos.astype(np.float32), motion.local_quats.astype(np.float32), rest, fps, int(motion.frame[0]), meta
    )


def bind_motion(
    asset: AvatarAsset, motion: LoadedMotion, fps: float, ped_id: int | None = None
) -> tuple[AvatarAsset, MotionCache]:
    """Scale ``asset`` to the motion's height and build its motion cache (rest skeleton = the scaled avatar's).

    ``ped_id``: the pedestrian's id (default: the motion's meta, −1 without one).
    """
    identity = _Identity(asset.avatar_id, asset.height_m, asset.rest_joints, asset.meta.get("sha256", ""))
    cache = _motion_cache(identity, motion, fps, ped_id)
    return asset.scaled(cache.meta["scale"]), cache


def run_binding(ctx: StageContext) -> list[str]:
    """Stage entry: bind every pedestrian's motion to an avatar and write its caches."""
    cfg = ctx.config.binding
    pool = ensure_pool(cfg)
    scene = SceneFolder(ctx.scene_dir)
    motions = _motions(scene)
    out_dir = scene.binding_dir
    if out_dir.exists():
        shutil.rmtree(out_dir)  # a rerun replaces the whole folder (no stale caches of removed pedestrians)
    out_dir.mkdir(parents=True)
    picks = identity_picks(ctx.config, ctx.scene_id, _scene_ped_ids(scene, [k for k, _ in motions]), len(pool))
    entries, written = [], []
    full: dict[Path, AvatarAsset] = {}  # whole assets, for materialised caches: read once per identity per scene
    for ped_id, motion in motions:
        path = pool[picks[ped_id]]
        identity = _verified_identity(path)
        cache = _motion_cache(identity, motion, float(motion.meta.get("fps", ctx.config.crowd.fps)), ped_id)
        cache_file = CACHE_FILE.format(ped_id=ped_id)
        write_compact_cache(scene.path(cache_file), cache.root_pos, cache.local_quats, cache.rest_joints, cache.meta)
        written.append(cache_file)
        materialized = None
        if cfg.materialize:
            materialized = MATERIALIZED_FILE.format(ped_id=ped_id)
            if path not in full:
                full[path] = load_avatar(path)
            write_materialized_cache(scene.path(materialized), full[path].scaled(cache.meta["scale"]), cache)
            written.append(materialized)
        entries.append(
            BindingRecord(
                ped_id=ped_id,
                avatar_id=identity.avatar_id,
                asset_path=str(path.resolve()),
                asset_sha256=identity.sha256,
                cache_file=cache_file,
                materialized_file=materialized,
                height_m=cache.meta["height_m"],
                scale=cache.meta["scale"],
            )
        )
    write_bindings(scene.bindings, Bindings(pedestrians=entries, pool_size=len(pool)))
    return [*written, BINDINGS_FILE]
