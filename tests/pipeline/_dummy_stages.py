"""Two tiny stages for chain tests (loaded through SONG_STAGE_PLUGINS so spawned workers see them)."""

from __future__ import annotations

import os
import time

import numpy as np

from song.errors import SceneError
from song.pipeline.chain import Stage, StageContext, register_stage
from song.util import write_json_atomic, write_npz_atomic


def _first(ctx: StageContext) -> list[str]:
    if ctx.scene.semantic_map.venue_type == "library":  # the "corrupted" scene of the tests
        raise SceneError(ctx.scene.root / "semantic_map.json", "venue_type", "dummy stage refuses libraries")
    time.sleep(float(os.environ.get("SONG_DUMMY_SLEEP", "0")))
    free = int(ctx.scene.occupancy.free.sum())
    write_json_atomic(ctx.scene_dir / "first.json", {"free": free, "draw": int(ctx.rng("a").integers(1 << 30))})
    return ["first.json"]


def _second(ctx: StageContext) -> list[str]:
    data = (ctx.scene_dir / "first.json").read_bytes()
    write_npz_atomic(ctx.scene_dir / "second.npz", x=np.frombuffer(data, dtype=np.uint8), y=ctx.rng().random(4))
    return ["second.npz"]


register_stage(Stage(name="dummy_first", run=_first, depends=(), reads=("scenes",)))
register_stage(Stage(name="dummy_second", run=_second, depends=("dummy_first",)))
