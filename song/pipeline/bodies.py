"""Who each pedestrian is, bodily: its height (from the motion stage's style) and avatar identity (from the pool).

Both are pure functions of (run seed, scene id, pedestrian id, config), so the crowd stage can ask for a
pedestrian's body before the motion and binding stages make it -- and gets the body those stages make:

- the height is the one :func:`song.pipeline.motion.gait.style_for` draws from the motion seed of
  :func:`motion_seed` (every motion generator uses that style);
- the identity is the one :func:`identity_picks` draws over the scene's pedestrians in id order
  (successive permutations of the pool, as the binding stage always drew them);
- the body radius (:func:`body_radii`) is the identity's measured radius (``body_radius_m`` in the
  asset's metadata: half the larger of its shoulder and hip breadth, + 4 cm) scaled, as binding scales
  the whole avatar, to the pedestrian's height.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from song.config import SongConfig
from song.errors import FormatError
from song.pipeline.chain import stage_rng


def motion_seed(config: SongConfig, scene_id: str, ped_id: int) -> int:
    """The seed of pedestrian ``ped_id``'s motion (its gait style and height), as the motion stage draws it."""
    return int(stage_rng(config, scene_id, "motion", ped_id).integers(0, 2**63 - 1))


def body_height(config: SongConfig, scene_id: str, ped_id: int) -> float:
    """Pedestrian ``ped_id``'s body height, m: the one its motion will have."""
    from song.pipeline.motion.gait import style_for

    return style_for(motion_seed(config, scene_id, ped_id), config.motion).height_m


def identity_picks(config: SongConfig, scene_id: str, ped_ids: Sequence[int], pool_size: int) -> dict[int, int]:
    """Pool index of each pedestrian: successive random permutations of the pool over the ids in order.

    No identity repeats within a scene while the pool allows. The ids are those of the scene's intents
    (every pedestrian the crowd could keep), so a pedestrian's identity does not depend on whether
    another one could start.
    """
    rng = stage_rng(config, scene_id, "binding", "identity")
    order: list[int] = []
    ids = sorted(int(i) for i in ped_ids)
    while len(order) < len(ids):
        order += rng.permutation(pool_size).tolist()
    return dict(zip(ids, order, strict=False))


def avatar_body(path: str | Path) -> tuple[float, float | None]:
    """``(height_m, body_radius_m or None)`` from an avatar asset's metadata alone (its arrays unread).

    Raises:
        FormatError: the file is not an avatar asset with a readable ``meta_json``.
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive, archive.open("meta_json.npy") as member:
            meta = json.loads(np.lib.format.read_array(member, allow_pickle=False).tobytes().decode("utf-8"))
        height = float(meta["height_m"])
        radius = meta.get("body_radius_m")
        return height, (float(radius) if radius is not None else None)
    except (OSError, KeyError, ValueError, TypeError, zipfile.BadZipFile) as exc:
        raise FormatError(path, "meta_json", f"cannot read the avatar's height and body radius ({exc})") from None


def body_radii(config: SongConfig, scene_id: str, ped_ids: Sequence[int]) -> dict[int, float]:
    """Each pedestrian's body radius, m: its avatar's measured radius scaled to its height.

    Capped at ``crowd.agent_radius_m``, the clearance the navmesh keeps from walls (a wider body would
    brush them); an imported avatar without a measured radius keeps ``crowd.agent_radius_m``.
    """
    from song.pipeline.binding.pool import ensure_pool

    pool = ensure_pool(config.binding)
    picks = identity_picks(config, scene_id, ped_ids, len(pool))
    cap = config.crowd.agent_radius_m
    bodies: dict[int, tuple[float, float | None]] = {}
    radii = {}
    for ped_id, pick in picks.items():
        height, radius = bodies.setdefault(pick, avatar_body(pool[pick]))
        if radius is None:
            radii[ped_id] = cap
        else:
            radii[ped_id] = min(cap, radius * body_height(config, scene_id, ped_id) / height)
    return radii
