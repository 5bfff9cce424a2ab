"""The avatar-free ablation (the paper's Table 3): the same episodes with nobody in them."""

from __future__ import annotations

import dataclasses

from song.datasets.bench.types import Episode


def without_avatars(episode: Episode) -> Episode:
    """``episode`` without pedestrians: no avatar is rendered, none collides, no sensor reports one.

    Start, goal, path, map, time limit and grading stay as released, so outcomes differ from the main
    run only by the people (a map baseline whose path meets nobody gets identical results).
    """
    return dataclasses.replace(episode, pedestrians=[], avatars=[])
