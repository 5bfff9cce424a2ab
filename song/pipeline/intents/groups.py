"""Pedestrians who walk together: groups of 2–4 formed from a scene's intents, whatever model proposed them.

Most people in public places walk with others (Moussaïd et al. 2010, PLoS ONE 5(4) e10047: 50–70 % of
pedestrians in groups, mostly pairs). Sizes follow the zero-truncated Poisson that fits free-forming
groups (Coleman & James 1961, Sociometry 24(1)); its one parameter follows from the share of people in
groups, since under it the share walking alone is e^−λ: λ = −ln(1 − ``intents.group_share``). Sizes
above ``MAX_SIZE`` are cut to it.

A group takes its first member's routine (the leader): the others start beside the leader's start, leave
when it leaves, at the group's speed (the slowest member's), and stand beside the leader at every stop
(standing spots ``SPOT_M`` from the leader's, on the walkable area, clear of everyone else's). A member
for whom no spot is free at its start or a stop stays on its own routine.
"""

from __future__ import annotations

import math

import numpy as np

from song.datasets.run.intents import Intent
from song.pipeline.intents.navigation import Walkable

MAX_SIZE = 4
SPOT_M = (0.8, 1.0, 1.2)  # distances from the leader's spot a member's spot is looked for at
SPOT_DIRECTIONS = 16
STANDING_ROOM_M = 0.05  # a spot keeps this beyond the body from obstacles


def group_sizes(share: float, count: int, rng: np.random.Generator) -> list[int]:
    """Sizes of consecutive groups covering ``count`` pedestrians (zero-truncated Poisson, cut at ``MAX_SIZE``)."""
    if share <= 0.0:
        return [1] * count
    lam = -math.log(1.0 - share)
    n = np.arange(1, MAX_SIZE + 1)
    pmf = lam**n / np.array([math.factorial(int(k)) for k in n])  # ∝ e^−λ λⁿ / n! (1 − e^−λ): the constants cancel
    pmf /= pmf.sum()
    sizes: list[int] = []
    while sum(sizes) < count:
        sizes.append(min(int(rng.choice(n, p=pmf)), count - sum(sizes)))
    return sizes


def _spot(walk: Walkable, centre: np.ndarray, taken: list[np.ndarray], separation: float) -> np.ndarray | None:
    """A walkable standing spot ``SPOT_M`` from ``centre``, at least ``separation`` from every taken one."""
    angles = np.arange(SPOT_DIRECTIONS) * 2 * np.pi / SPOT_DIRECTIONS
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    grid = walk.package.occupancy
    for radius in SPOT_M:
        spots = centre + radius * ring
        ok = walk.on_main(spots)
        rc = np.clip(grid.to_cell(spots), 0, np.array(grid.shape) - 1)
        ok &= walk.clearance[rc[:, 0], rc[:, 1]] >= walk.radius + STANDING_ROOM_M
        if taken:
            ok &= np.linalg.norm(spots[:, None] - np.asarray(taken)[None], axis=-1).min(axis=1) >= separation
        if ok.any():
            return spots[int(np.flatnonzero(ok)[0])]
    return None


def form_groups(intents: list[Intent], walk: Walkable, share: float, separation: float, rng) -> list[Intent]:
    """The intents with groups formed (see the module doc); ids and order are kept."""
    if share <= 0.0 or len(intents) < 2:
        return list(intents)
    out = list(intents)
    taken = [np.asarray(i.start_xy) for i in intents] + [np.asarray(leg.goal_xy) for i in intents for leg in i.route()]
    at = 0
    for size in group_sizes(share, len(intents), rng):
        leader, members = out[at], []
        for k in range(at + 1, at + size):
            start = _spot(walk, np.asarray(leader.start_xy), taken, separation)
            legs = []
            for leg in leader.route() if start is not None else []:
                spot = _spot(walk, np.asarray(leg.goal_xy), [*taken, start, *legs_xy(legs)], separation)
                if spot is None:
                    break
                legs.append(leg.model_copy(update={"goal_xy": (round(float(spot[0]), 4), round(float(spot[1]), 4))}))
            if start is None or len(legs) < len(leader.route()):
                continue  # no room beside the leader: it keeps its own routine
            taken += [start, *legs_xy(legs)]
            members.append((k, start, legs))
        if members:
            speed = min([leader.speed] + [out[k].speed for k, _, _ in members])
            out[at] = leader.model_copy(update={"group": leader.id, "speed": speed})
            for k, start, legs in members:
                out[k] = out[k].model_copy(
                    update={
                        "group": leader.id,
                        "speed": speed,
                        "depart_time": leader.depart_time,
                        "start_object": leader.start_object,
                        "start_xy": (round(float(start[0]), 4), round(float(start[1]), 4)),
                        "activity": leader.activity,
                        "goal_object": leader.goal_object,
                        "goal_xy": legs[0].goal_xy,
                        "geodesic_m": leader.geodesic_m,
                        "legs": legs,
                    }
                )
        at += size
    return out


def legs_xy(legs) -> list[np.ndarray]:
    """The goal points of legs, as arrays."""
    return [np.asarray(leg.goal_xy) for leg in legs]
