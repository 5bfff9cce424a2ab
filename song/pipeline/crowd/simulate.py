"""Joint crowd simulation at 30 FPS on the navmesh, with DetourCrowd's structure.

Per pedestrian, per frame (DetourCrowd's ``dtCrowd::update`` order):

1. path corridor: the exact shortest path on the navmesh as corner points; a corner is passed when
   reached, or (every 1/3 s, turn anticipation) as soon as the corner after it is visible; a pedestrian
   pushed out of sight of its corner gets a short detour back to it (a local replan);
2. steering toward the next corner with Detour's smooth steer direction (the next-but-one corner pulls
   the heading early), slowing down within 2r of the goal;
3. local avoidance among all pedestrians and the walls, through the avoidance seam
   (:mod:`song.pipeline.crowd.avoidance`; ``crowd.avoidance = "orca"``: ORCA against the navmesh grown
   back by r + 5 mm, i.e. the un-eroded free space, so a pedestrian on the mesh never overlaps a wall);
4. acceleration limits: a turn of up to 90° keeps the speed, the heading turning at the sideways
   acceleration ``crowd.turn_accel_mps2`` (1 m/s²); the speed changes by at most ``crowd.max_accel_mps2``
   (2 m/s²), and starting, stopping and turning back clamp the velocity change to it;
   moves constrained to the navmesh (sliding along its boundary); overlap resolution passes (pairs
   pushed apart within each pedestrian's speed budget, again on the mesh);
5. stall detection: no progress along the path for ``stall_time_s`` → a full replan around everyone
   standing (Detour's temporary obstacles); stalled again → the pedestrian yields: it steps out of the
   way of the walkers around it (to a free spot 0.7 or 1.4 m away, the one farthest from their ways),
   waits there ``YIELD_S`` and walks on; after ``MAX_YIELDS`` yields a further stall is final: a walker
   with stops still ahead gives this one up and walks on to its next (recorded in its status's
   ``skipped_stops``); one on its last leg gives its routine up, steps out of the others' way and
   stands there (status ``gave_up``). (Stepping aside instead of standing still where it stalled: 3
   against 3 through a 1.0 m door all arrive, 5 of 6 before; in the generated lobby 30-32 of 32 arrive,
   26 before.)
6. hindsight (``crowd.give_up_in_hindsight``): the plan is made offline, so a walker that gives a stop
   up can know it will. Where one gave up more than ``stall_time_s`` after it last got nearer that stop
   (its tries: replan, step-asides, each with some progress along a new path but none toward the stop),
   the crowd is simulated again with a decision: ``stall_time_s`` after that last progress (its first
   stall) it gives the stop up at once, stepping aside, or walking on to its next. Up to the first
   decision the new run is the old one frame for frame; after it others may fare differently, so a
   decision holds only for a walker still where it stood when it was made (:func:`_decide`), and this
   repeats while new late give-ups appear, at most ``HINDSIGHT_PASSES`` times.

Nobody is removed once the simulation runs, so it runs once, from the earliest departure to the end
(a walker stalled for good gives up and stays in the scene; docs/crowd.md). Only pedestrians that cannot
start (off the mesh, unreachable goals, overlapping starts) are left out, before the first frame.

Pedestrians exist for the whole scenario: they stand at their start until departure, walk their
routine's legs with a dwell at every intermediate stop, and stand at the last goal after arriving;
others avoid them while they stand (the contract of ``crowd.parquet``). One due to walk
off lets a walker coming by go first (:func:`_wait_for_passers`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from song.config import CrowdConfig
from song.datasets.run.intents import Intent
from song.geometry.navmesh import Navmesh, carve_discs
from song.geometry.outline import nearest_on_outline
from song.pipeline.crowd._crowd_kernel import (
    avoidance_inputs,
    hold_starts,
    progress,
    reached_corners,
    record_frame,
    settle_moves,
    walking,
)
from song.pipeline.crowd.avoidance import LocalAvoidance
from song.pipeline.crowd.passages import Queues, find_passages

ARRIVE_M = 0.05  # within this of the goal a pedestrian has arrived (it then stands there)
CLOSE_ENOUGH_M = 0.5  # a pedestrian stalled this near its goal (a step) stops where it is: it has arrived
CHECK_EVERY = 10  # frames between visibility checks (turn anticipation, off-corridor detection): 1/3 s
CORNER_REACHED_M = 0.1  # closer than this to a corner, head for the next one (Detour's look-ahead)


def _length(v: np.ndarray) -> np.ndarray:
    """Length of 2-D vectors along the last axis.

    One ufunc call: ``np.linalg.norm`` costs ~3× more per call and runs ~16 times per frame.
    """
    return np.hypot(v[..., 0], v[..., 1])


PASSER_LOOKAHEAD_S, MAX_START_WAIT_S = 1.0, 3.0  # one about to walk off lets those this close in time pass first
YIELD_S, MAX_YIELDS = 3.0, 4  # a pedestrian still stalled after its replan stands aside this long, this often
PROGRESS_M = 0.1  # a pedestrian that gets no closer than this along its path in stall_time_s is stalled
# standing at an object (before departure, dwelling, after the last leg) a pedestrian turns to face it at this
# rate: a quarter turn on the spot in about a second (in-place turns of 90-180° take 1-2 s; Hase & Stein 1999)
FACE_TURN_RATE = np.pi / 2
ASIDE_M, ASIDE_DIRECTIONS = 0.7, 12  # how far, and among how many directions, someone steps aside
ASIDE_SCAN_M = 4.0  # a yielding walker steps out of the ways of the walkers this close
OVERLAP_PASSES = 5  # at most; three left a 1 cm overlap in a social-force crowd pressing three abreast (docs/crowd.md)
OVERLAP_MARGIN_M = 0.002  # overlap passes separate centres to 2r + this
SEPARATION_REACH_M = 0.15  # beyond 2r + this (two frames' steps at 1.8 m/s, and more) no overlap pass joins two people
# a replan keeps this much more than body contact from everyone standing: a path squeezed past someone at
# 2r (a wall on the other side) is legal but leaves avoidance no room, and the walker stalls in it again
REPLAN_CLEARANCE_M = 0.1
MAX_SNAP_M = 0.5  # start and goal may be this far off the mesh (they are snapped onto it)
# hindsight: a stop given up more than stall_time_s + HINDSIGHT_SLACK_S after the walker last got nearer it is
# given up stall_time_s after that instead, in a new run (at most HINDSIGHT_PASSES); progress sampled this often
HINDSIGHT_PASSES, HINDSIGHT_SLACK_S, HINDSIGHT_EVERY = 6, 0.5, 3
HINDSIGHT_NEAR_M = 0.5  # a decision made in an earlier run holds for a walker this near where it stood then
SLOT_M = 1.2  # a group member walks this far beside (or behind) its leader: beyond the comfort distance ORCA keeps
FORMATION_S = 1.0  # a member closes the gap to its slot in about this long
CATCH_UP = 1.4  # a member may walk this much faster than the group to keep up
NEAR_STOP_M = 1.5  # this near its stop, a member (or its leader) walks to its own spot there
GROUP_HOLD_S = 0.2  # a leader waiting for a member at a stop checks again after this


@dataclass
class CrowdPlan:
    """Joint trajectories of the kept pedestrians.

    Attributes:
        ped_ids: (P,) int. xy: (P, F, 2) m. yaw: (P, F) rad. speed: (P, F) m/s. fps: frames per second.
        status: per pedestrian id: {"status": "arrived" | "gave_up" | "timeout" | "removed", "reason",
            "arrival_s", "skipped_stops"} (:class:`song.datasets.run.PedestrianStatus`).
    """

    ped_ids: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    fps: int
    status: dict[int, dict] = field(default_factory=dict)


@dataclass
class _Walkers:
    """Mutable per-pedestrian state of one simulation run (arrays over the N pedestrians)."""

    pos: np.ndarray  # (N, 2) m
    vel: np.ndarray  # (N, 2) m/s
    goal: np.ndarray  # (N, 2) m, on the mesh
    speed: np.ndarray  # (N,) preferred speed, m/s
    depart: np.ndarray  # (N,) s
    paths: list[np.ndarray]  # corners (K, 2) after the start, the last one the goal
    suffix: list[np.ndarray]  # (K,) path length from each corner to the goal, m
    corner: np.ndarray  # (N,) index of the corner being steered to
    cur: np.ndarray  # (N, 2) that corner, m
    nxt: np.ndarray  # (N, 2) the corner after it (the goal when there is none), m
    has_next: np.ndarray  # (N,) bool: the current corner is not the goal
    rest: np.ndarray  # (N,) path length from the current corner to the goal, m
    arrived: np.ndarray  # (N,) bool
    arrival: np.ndarray  # (N,) s: when it finished its routine (nan: not yet)
    best: np.ndarray  # (N,) shortest remaining path length seen, m
    last_progress: np.ndarray  # (N,) s
    replanned: np.ndarray  # (N,) str: why the stall replan did not help ("" until one is used)
    yield_until: np.ndarray  # (N,) s: a pedestrian stalled after replanning stands aside until then
    yields: np.ndarray  # (N,) int: how often it has yielded
    heading: np.ndarray  # (N,) rad
    smooth: np.ndarray  # (N, 2) smoothed velocity, m/s
    # per pedestrian: legs' goals (on the mesh), dwells, step aside?, the outline of the object there (or None)
    stops: list[list[tuple[np.ndarray, float, bool, np.ndarray | None]]]
    leg: np.ndarray  # (N,) int: the leg being walked
    dwell_until: np.ndarray  # (N,) s: standing at an intermediate stop until then
    face: np.ndarray  # (N, 2) the point a pedestrian standing at an object turns to (nan: none, or walking), m
    waited: np.ndarray  # (N,) s: how long the pedestrian has put off walking off, for someone passing close
    skipped: list[list[int]]  # per pedestrian: the routine stops (indices into Intent.route()) it gave up
    gave_up: np.ndarray  # (N,) s: when it gave its routine up, stalled for good on its last leg (nan: never)
    leader: np.ndarray  # (N,) index of its group's leader (−1: it leads, or walks alone)
    member: np.ndarray  # (N,) its place in its group (0: the leader, or alone)
    abreast: np.ndarray  # (N,) bool: its slot beside the leader is free (checked every CHECK_EVERY frames)
    radius: np.ndarray  # (N,) body radius, m (at most the navmesh's agent radius)
    leg_began: np.ndarray  # (N,) s: when it set off for the routine stop it is walking to
    # per pedestrian: the routine stops it gave up, as (index in Intent.route(), where, set off for it, gave it up)
    given_up: list[list[tuple[int, np.ndarray, float, float]]] = field(default_factory=list)
    # hindsight (:func:`plan_crowd`): (pedestrian, routine stop) -> (when it gives that stop up, s; where it is then)
    decide: dict[tuple[int, int], tuple[float, np.ndarray]] = field(default_factory=dict)
    decided: set[int] = field(default_factory=set)  # pedestrians that gave their routine up by such a decision


def _to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M,) distance from each point (M, 2) to the nearest of the segments a→b (S, 2), m."""
    ab = b - a
    s = np.clip(((points[:, None] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    return _length(points[:, None] - (a + s[..., None] * ab)).min(axis=1)


def _suffix(path: np.ndarray) -> np.ndarray:
    steps = _length(np.diff(path, axis=0))
    return np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])


def _refresh(w: _Walkers, ks) -> None:
    """Recompute the cached corner arrays of pedestrians ``ks`` after their corner or path changed."""
    for k in ks:
        path, c = w.paths[k], w.corner[k]
        w.cur[k], w.nxt[k] = path[c], path[min(c + 1, len(path) - 1)]
        w.has_next[k], w.rest[k] = c < len(path) - 1, w.suffix[k][c]


def _set_path(w: _Walkers, k: int, path: np.ndarray) -> None:
    w.paths[k], w.suffix[k], w.corner[k] = path, _suffix(path), 0
    _refresh(w, [k])


def _advance(w: _Walkers, ks: np.ndarray) -> None:
    w.corner[ks] += 1
    _refresh(w, ks)


def _remaining(w: _Walkers, idx: np.ndarray) -> np.ndarray:
    """(M,) path length still to walk, m: to the current corner, then along the remaining corners."""
    return _length(w.cur[idx] - w.pos[idx]) + w.rest[idx]


def _plan(mesh: Navmesh, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
    res = mesh.find_path(start, goal, max_snap=MAX_SNAP_M, allow_partial=False)
    if res.status != "ok":
        return None
    return res.points[1:] if len(res.points) > 1 else res.points


def _nearest_on_outline(outline: np.ndarray | None, point: np.ndarray) -> np.ndarray:
    """The point of a closed outline (K, 2) nearest ``point`` (2,), m; nan when there is no outline."""
    if outline is None or not len(outline):
        return np.full(2, np.nan)
    return nearest_on_outline(outline, point[None])[0][0]


def _start(
    intents: list[Intent], mesh: Navmesh, jitter: np.ndarray, outlines: dict[str, np.ndarray], radius: np.ndarray
):  # fmt: skip
    """Snapped, jittered starts; every leg's goal snapped; first paths. Returns (walkers, failures {index: reason}).

    ``jitter`` (N, 2) m: each pedestrian's own start offset (drawn once per intent, so whom else the
    crowd keeps never changes it). ``outlines``: object footprints by id; someone standing at its start
    object or at a leg's faces the nearest point of its outline. ``radius`` (N,): body radii, m.
    """
    n = len(intents)
    raw = np.array([i.start_xy for i in intents], dtype=np.float64).reshape(n, 2)
    routes = [i.route() for i in intents]
    pos, tri, _ = mesh.snap(raw, MAX_SNAP_M)
    stops, failures = [], {}
    for k, route in enumerate(routes):
        goals, gtri, _ = mesh.snap(np.array([leg.goal_xy for leg in route], dtype=np.float64), MAX_SNAP_M)
        stops.append(
            [(goals[j], float(leg.dwell_s), False, outlines.get(leg.goal_object)) for j, leg in enumerate(route)]
        )
        if (gtri < 0).any():
            failures[k] = f"goal of leg {int(np.argmax(gtri < 0)) + 1} is more than {MAX_SNAP_M} m off the navmesh"
        elif tri[k] >= 0 and len({int(mesh.component[t]) for t in [tri[k], *gtri]}) > 1:
            failures[k] = "a leg's goal is not reachable on the navmesh"
    goal = np.array([s[0][0] for s in stops]).reshape(n, 2)
    if n:
        pos = np.where((tri >= 0)[:, None], mesh.constrain_moves(pos, pos + jitter), pos)
    paths: list[np.ndarray] = []
    for k in range(n):
        path = _plan(mesh, pos[k], goal[k]) if tri[k] >= 0 and k not in failures else None
        if tri[k] < 0:
            failures[k] = f"start is more than {MAX_SNAP_M} m off the navmesh"
        elif path is None and k not in failures:
            failures[k] = "goal is not reachable on the navmesh"
        paths.append(path if path is not None else goal[k : k + 1].copy())
    d = _length(pos[:, None] - pos[None]) + np.triu(np.full((n, n), np.inf))
    for k, j in zip(*np.nonzero(d < radius[:, None] + radius[None]), strict=True):  # too crowded to stand there
        if k not in failures and j not in failures:
            failures[int(k)] = f"start overlaps pedestrian {intents[int(j)].id}"
    first = np.array([p[0] for p in paths]).reshape(n, 2)
    face = np.array([_nearest_on_outline(outlines.get(i.start_object), pos[k]) for k, i in enumerate(intents)])
    face = face.reshape(n, 2)
    toward = np.where(np.isnan(face), first, face)  # standing at its start object, or facing its way
    heading = np.arctan2(toward[:, 1] - pos[:, 1], toward[:, 0] - pos[:, 0])
    depart = np.array([i.depart_time for i in intents], dtype=np.float64)
    leader = _groups(intents)
    w = _Walkers(
        pos=pos,
        vel=np.zeros((n, 2)),
        goal=goal,
        speed=np.array([i.speed for i in intents], dtype=np.float64),
        depart=depart,
        paths=paths,
        suffix=[_suffix(p) for p in paths],
        corner=np.zeros(n, dtype=np.int64),
        cur=np.zeros((n, 2)),
        nxt=np.zeros((n, 2)),
        has_next=np.zeros(n, dtype=bool),
        rest=np.zeros(n),
        arrived=np.zeros(n, dtype=bool),
        arrival=np.full(n, np.nan),
        best=np.zeros(n),
        last_progress=depart.copy(),
        replanned=np.full(n, "", dtype=object),
        yield_until=np.zeros(n),
        yields=np.zeros(n, dtype=np.int64),
        heading=heading,
        smooth=np.zeros((n, 2)),
        stops=stops,
        leg=np.zeros(n, dtype=np.int64),
        dwell_until=np.zeros(n),
        face=face,
        waited=np.zeros(n),
        skipped=[[] for _ in range(n)],
        gave_up=np.full(n, np.nan),
        leader=leader,
        member=np.array([(leader[:k] == leader[k]).sum() + 1 if leader[k] >= 0 else 0 for k in range(n)], np.int64),
        abreast=np.ones(n, bool),
        radius=radius,
        leg_began=depart.copy(),
        given_up=[[] for _ in range(n)],
    )
    _refresh(w, range(n))
    w.best = _remaining(w, np.arange(n))
    return w, failures


def _groups(intents: list[Intent]) -> np.ndarray:
    """(N,) index of each pedestrian's group leader among ``intents`` (−1: the leader itself, or alone)."""
    index = {i.id: k for k, i in enumerate(intents)}
    return np.array(
        [index.get(i.group, -1) if i.group is not None and i.group != i.id else -1 for i in intents], dtype=np.int64
    )


def _formation(w: _Walkers, mesh: Navmesh, rows: np.ndarray, moving: np.ndarray, inputs: list, check: bool) -> None:
    """Group members walk with their leader: the avoidance's preferred velocities and speed limits, in place.

    A member on the same leg as its leader, both walking and the member not yet near its own stop, heads
    for its slot: abreast of the leader (``SLOT_M`` to its right, then left, then two to the right) where
    that spot is on the mesh in sight of the leader, else in file behind it; its preferred velocity is the
    leader's plus the way to the slot over ``FORMATION_S``, up to ``CATCH_UP`` times its speed. A leader
    slows for a member lagging behind its slot. (Moussaïd et al. 2010: pairs walk abreast at low density.)
    """
    followers = np.flatnonzero((w.leader >= 0) & moving)
    if not len(followers):
        return
    where = np.full(len(w.pos), -1, dtype=np.int64)
    where[rows] = np.arange(len(rows))
    _, velocities, preferred, _, limits, _ = inputs
    lag: dict[int, float] = {}
    for k in followers:
        lead = int(w.leader[k])
        if not moving[lead] or w.leg[k] != w.leg[lead] or where[k] < 0 or where[lead] < 0:
            continue
        if _length(w.goal[k] - w.pos[k]) < NEAR_STOP_M or _length(w.goal[lead] - w.pos[lead]) < NEAR_STOP_M:
            continue  # each goes to its own spot at the stop
        v_lead = velocities[where[lead]] if _length(velocities[where[lead]]) > 0.2 else preferred[where[lead]]
        heading = v_lead / max(float(_length(v_lead)), 1e-9)
        right = np.array([heading[1], -heading[0]])
        m = int(w.member[k])
        side = SLOT_M * (1.0 if m % 2 else -1.0) * ((m + 1) // 2)
        beside = w.pos[lead] + right * side
        if check:
            w.abreast[k] = bool(
                mesh.contains(beside[None])[0] and mesh.segment_clear(w.pos[lead][None], beside[None])[0]
            )
        slot = beside if w.abreast[k] else w.pos[lead] - heading * SLOT_M * m
        want = v_lead + (slot - w.pos[k]) / FORMATION_S
        cap = CATCH_UP * w.speed[k]
        size = float(_length(want))
        preferred[where[k]] = want * min(1.0, cap / max(size, 1e-9))
        limits[where[k]] = max(limits[where[k]], cap)
        lag[lead] = max(lag.get(lead, 0.0), float(_length(slot - w.pos[k])))
    for lead, behind in lag.items():
        preferred[where[lead]] *= float(np.clip(1.2 - behind, 0.3, 1.0))


def _hold_for_group(w: _Walkers, t: float) -> None:
    """At a stop a group waits for its members, then leaves together.

    A leader dwelling (or about to leave) while a member is still on its way to this stop stays; once the
    leader walks on, members standing at the stop leave with it.
    """
    for k in np.flatnonzero(w.leader >= 0):
        lead = int(w.leader[k])
        if w.arrived[k] or w.arrived[lead]:
            continue
        if w.leg[k] < w.leg[lead] and w.dwell_until[lead] > t - 1e-9:
            w.dwell_until[lead] = max(w.dwell_until[lead], t + GROUP_HOLD_S)
        elif w.leg[k] == w.leg[lead] and w.dwell_until[k] > t and w.dwell_until[lead] <= t:
            w.dwell_until[k] = t


def _next_leg(w: _Walkers, mesh: Navmesh, k: int, t: float) -> bool:
    """Pedestrian k reached its current stop: dwell there, then walk the next leg. False when it was the last."""
    stops, leg = w.stops[k], int(w.leg[k])
    if leg + 1 >= len(stops):
        return False
    w.dwell_until[k] = t + stops[leg][1]
    w.leg[k] = leg + 1
    w.goal[k] = stops[leg + 1][0]
    path = _plan(mesh, w.pos[k], w.goal[k])
    _set_path(w, k, path if path is not None else w.goal[k : k + 1].copy())
    w.best[k] = _remaining(w, np.array([k]))[0]
    w.last_progress[k] = w.dwell_until[k]
    w.waited[k] = 0.0
    if not stops[leg][2]:  # a step aside is part of the leg it interrupts
        w.replanned[k], w.yields[k] = "", 0
        w.leg_began[k] = w.dwell_until[k]
    return True


def _routine_stop(w: _Walkers, k: int) -> int:
    """The index in its routine (``Intent.route()``) of the stop walker k is on its way to (steps aside not counted)."""
    return sum(not aside for _, _, aside, _ in w.stops[k][: int(w.leg[k])])


def _decide(w: _Walkers, mesh: Navmesh, moving: np.ndarray, t: float, radius: float) -> None:
    """Hindsight (:func:`plan_crowd`): walkers whose decision time has come give their stop up now.

    A decision holds where it was made: walker k still on its way to that stop, on the try that began
    before the decision, and within ``HINDSIGHT_NEAR_M`` of where it stood then (after an earlier decision
    changed the crowd, it may fare better this time). A step aside under way ends; then :func:`_skip_stop`,
    or on the last leg :func:`_give_up`.
    """
    for (k, stop), (when, where) in list(w.decide.items()):
        if when > t:
            continue
        del w.decide[(k, stop)]
        if w.arrived[k] or _routine_stop(w, k) != stop or w.leg_began[k] > when:
            continue
        if _length(w.pos[k] - where) > HINDSIGHT_NEAR_M:
            continue
        leg = int(w.leg[k])
        if w.stops[k][leg][2]:  # on its way to a spot aside: that step aside is over
            del w.stops[k][leg]
            w.goal[k] = w.stops[k][leg][0]
        w.yield_until[k] = min(w.yield_until[k], t)
        w.dwell_until[k] = min(w.dwell_until[k], t)  # waiting at a spot aside
        if not _skip_stop(w, mesh, k, t):
            w.decided.add(k)
            _give_up(w, mesh, k, moving, radius, t)


def _skip_stop(w: _Walkers, mesh: Navmesh, k: int, t: float) -> bool:
    """Walker k, stalled for good on its way to a stop that is not its last, gives that errand up and walks on.

    The stop is recorded in ``w.skipped`` (its index in the routine) and k heads for its next stop at
    once, without the dwell. False when the stop is its last (k then gives its routine up, :func:`_give_up`).
    """
    leg = int(w.leg[k])
    if leg + 1 >= len(w.stops[k]):
        return False
    stop = _routine_stop(w, k)
    w.skipped[k].append(stop)
    w.given_up[k].append((stop, w.stops[k][leg][0].copy(), float(w.leg_began[k]), t))
    _next_leg(w, mesh, k, t)
    w.dwell_until[k] = w.last_progress[k] = w.leg_began[k] = t
    return True


def _give_up(w: _Walkers, mesh: Navmesh, k: int, moving: np.ndarray, radius: float, t: float) -> None:
    """Walker k, stalled for good on its last leg, gives its routine up: it steps out of the way and stands there.

    Its step aside (:func:`_step_aside`) becomes its last stop; with no spot free it stands where it is.
    Like anyone who has finished, it steps aside again when it blocks a walker (:func:`_make_room`).
    """
    w.gave_up[k] = t
    leg = int(w.leg[k])
    w.given_up[k].append((_routine_stop(w, k), w.stops[k][leg][0].copy(), float(w.leg_began[k]), t))
    if _step_aside(w, mesh, k, moving, radius, t):
        del w.stops[k][leg + 1 :]  # the stop it gave up
    else:
        _stand(w, k, t)


def _finish(w: _Walkers, k: int, t: float) -> None:
    """Pedestrian k has finished at time t and stands.

    Its first finish is its arrival: a step aside to make room for a walker afterwards keeps that time.
    """
    w.arrived[k] = True
    if np.isnan(w.arrival[k]):
        w.arrival[k] = t


def _stand(w: _Walkers, k: int, t: float) -> None:
    """Pedestrian k has finished where it is at time t."""
    _finish(w, k, t)
    w.goal[k], w.vel[k] = w.pos[k].copy(), 0.0


def _step_aside(w: _Walkers, mesh: Navmesh, k: int, moving: np.ndarray, radius: float, t: float) -> bool:
    """Stalled walker k yields: it steps out of the way of the walkers around it and waits there.

    The spot: among ``ASIDE_DIRECTIONS`` points at ``ASIDE_M`` and twice that around k, reachable in a
    straight line on the mesh and clear of everyone, the one farthest from the other walkers' ways
    (from where each stands to its next two corners) within ``ASIDE_SCAN_M``. k walks there, stands for
    ``YIELD_S`` and resumes its leg. False when no spot qualifies (k then waits where it is).
    """
    dist = _length(w.pos - w.pos[k])
    around = np.flatnonzero(dist < ASIDE_SCAN_M)
    angles = np.arange(ASIDE_DIRECTIONS) * 2 * np.pi / ASIDE_DIRECTIONS
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    spots = w.pos[k] + np.vstack([ASIDE_M * ring, 2 * ASIDE_M * ring])
    ok = mesh.contains(spots) & mesh.segment_clear(np.repeat(w.pos[k : k + 1], len(spots), axis=0), spots)
    others = around[around != k]
    if len(others):
        ok &= (_length(spots[:, None] - w.pos[None, others]) > 2 * radius + 0.1).all(axis=1)
    spots = spots[ok]
    if not len(spots):
        return False
    ways = [(w.pos[j], w.cur[j]) for j in others if moving[j]] + [
        (w.cur[j], w.nxt[j]) for j in others if moving[j] and w.has_next[j]
    ]
    if ways:
        score = _to_segments(spots, np.array([p for p, _ in ways]), np.array([q for _, q in ways]))
    else:
        score = -_length(spots - w.pos[k])
    spot = spots[int(np.argmax(score))]
    leg = int(w.leg[k])
    w.stops[k].insert(leg, (spot, YIELD_S, True, None))
    w.goal[k] = spot
    _set_path(w, k, spot[None].copy())
    w.best[k], w.last_progress[k] = _remaining(w, np.array([k]))[0], t
    return True


def _update_corners(w: _Walkers, mesh: Navmesh, moving: np.ndarray, check: bool) -> None:
    """Pass reached corners; on check frames pass corners whose successor is visible, detour when lost."""
    for _ in range(8):  # corners closer together than the look-ahead are passed in one frame
        reached = reached_corners(w.pos, w.cur, w.has_next, moving, CORNER_REACHED_M)
        if not len(reached):
            break
        _advance(w, reached)
    if not check:
        return
    for _ in range(4):  # turn anticipation: several corners may become visible at once
        ahead = np.flatnonzero(moving & w.has_next)
        if not len(ahead):
            break
        seen = ahead[mesh.segment_clear(w.pos[ahead], w.nxt[ahead])]
        if not len(seen):
            break
        _advance(w, seen)
    idx = np.flatnonzero(moving)
    for k in idx[~mesh.segment_clear(w.pos[idx], w.cur[idx])]:
        # pushed off the corridor: a short detour back to the current corner, then the old corridor
        detour = _plan(mesh, w.pos[k], w.cur[k])
        if detour is not None:
            _set_path(w, k, np.vstack([detour, w.paths[k][w.corner[k] + 1 :]]))


def _wait_for_passers(w: _Walkers, moving: np.ndarray, frame: int, cfg: CrowdConfig) -> None:
    """Pedestrians due to walk off in ``frame`` wait while a walker is passing closer than the comfort distance.

    People do not step out into someone's way: one about to leave a spot (its departure or the end of a
    dwell) waits while a walker would come within ``crowd.comfort_distance_m`` of it in the next
    ``PASSER_LOOKAHEAD_S`` (moving on as it does), for at most ``MAX_START_WAIT_S`` per start. Those
    waiting are taken out of ``moving`` (in place) and start at the earliest in the next frame.
    """
    hold_starts(
        w.pos, w.vel, w.depart, w.dwell_until, w.last_progress, w.waited, moving, frame, cfg.fps,
        PASSER_LOOKAHEAD_S, cfg.comfort_distance_m, MAX_START_WAIT_S,
    )  # fmt: skip


def _step_frame(
    w: _Walkers, mesh: Navmesh, avoid: LocalAvoidance, moving: np.ndarray, cfg: CrowdConfig, frame: int,
    queues: Queues | None,
):  # fmt: skip
    dt, r = 1.0 / cfg.fps, w.radius
    if not moving.any():
        w.vel = np.zeros_like(w.vel)
        return
    _update_corners(w, mesh, moving, frame % CHECK_EVERY == 0)
    cur, nxt, has_next, goal = w.cur, w.nxt, w.has_next, w.goal
    if queues is not None and (queues.passage >= 0).any():
        wait = queues.waiting & moving  # those waiting for a passage head for their places
        cur, nxt, goal = (np.where(wait[:, None], queues.hold, a) for a in (cur, nxt, goal))
        has_next = has_next & ~wait
        # waiting, or following others through, is not being stuck (for a while)
        w.last_progress[queues.patient(frame * dt) & moving] = frame * dt
    # avoidance for the walkers and whoever stands within their neighbour distance (others cannot change the answer)
    reach = max(avoid.neighbor_dist, 2 * float(r.max()) + SEPARATION_REACH_M)
    rows, *inputs = avoidance_inputs(
        w.pos, w.vel, cur, nxt, has_next, goal, w.speed, moving, r, dt, reach, frame, w.last_progress,
    )  # fmt: skip
    if (w.leader >= 0).any():
        _formation(w, mesh, rows, moving, inputs, frame % CHECK_EVERY == 0)
    new_vel = avoid.velocities(*inputs)
    w.pos, w.vel = settle_moves(
        w.pos, w.vel, rows, new_vel, moving, w.speed, dt, cfg.max_accel_mps2 * dt, r, OVERLAP_MARGIN_M, OVERLAP_PASSES,
        mesh.move_args(), cfg.turn_accel_mps2 * dt,
    )  # fmt: skip


def _check_progress(w: _Walkers, mesh: Navmesh, moving: np.ndarray, t: float, cfg: CrowdConfig) -> None:
    """Record arrivals at stops and at the end; replan, yield, skip a stop or give up for stalled pedestrians."""
    radius = cfg.agent_radius_m
    done, stalled = progress(
        w.pos, w.goal, w.cur, w.rest, w.best, w.last_progress, moving, t, ARRIVE_M, PROGRESS_M, cfg.stall_time_s
    )
    for k in done:
        aside = w.stops[k][w.leg[k]][2]
        w.face[k] = _nearest_on_outline(w.stops[k][w.leg[k]][3], w.pos[k])
        if not _next_leg(w, mesh, int(k), t):
            _finish(w, int(k), t)  # it stands where it is (no snap: a snap would exceed its speed)
        elif aside:
            _reroute_around_standing(w, mesh, int(k), moving, radius)
    for k in stalled:
        if _length(w.goal[k] - w.pos[k]) < CLOSE_ENOUGH_M:  # held a step from its spot: it stops where it is
            w.goal[k] = w.pos[k].copy()
            w.face[k] = _nearest_on_outline(w.stops[k][w.leg[k]][3], w.pos[k])
            if not _next_leg(w, mesh, int(k), t):
                _finish(w, int(k), t)
            continue
        if w.stops[k][w.leg[k]][2]:  # the crowd keeps it from its spot aside: it waits where it got to
            if not _next_leg(w, mesh, int(k), t):
                _stand(w, int(k), t)  # a last spot aside (it has finished, or given up): it stays there
                continue
            _reroute_around_standing(w, mesh, int(k), moving, radius)
            continue
        if w.replanned[k] and w.yields[k] < MAX_YIELDS:
            # deadlocked face to face: step out of the others' way for a while, then try again
            w.yields[k] += 1
            if not _step_aside(w, mesh, int(k), moving, radius, t):
                w.yield_until[k] = t + YIELD_S
                w.last_progress[k] = t + YIELD_S
                w.vel[k] = 0.0
            continue
        if w.replanned[k]:  # stalled for good: it gives up this stop, or its routine when the stop is the last
            if not _skip_stop(w, mesh, int(k), t):
                _give_up(w, mesh, int(k), moving, radius, t)
            continue
        w.last_progress[k] = t
        w.replanned[k] = _reroute_around_standing(w, mesh, int(k), moving, radius)
        if w.replanned[k].startswith("the way is blocked"):
            _make_room(w, mesh, k, moving, radius, t)


def _reroute_around_standing(w: _Walkers, mesh: Navmesh, k: int, moving: np.ndarray, radius: float):
    """Walker k takes a path around everyone standing (a stall replan; the way on after a step aside).

    Returns why a later stall would be final (:func:`_replan_around_standing`).
    """
    path, reason = _replan_around_standing(w, mesh, k, moving, radius)
    _set_path(w, k, path)
    w.best[k] = _remaining(w, np.array([k]))[0]
    return reason


def _make_room(w: _Walkers, mesh: Navmesh, k: int, moving: np.ndarray, radius: float, t: float) -> None:
    """People standing in stalled walker k's way make room.

    Anyone standing within 2r + 0.1 m of k's remaining path: one waiting to depart or dwelling at a
    stop leaves for its next leg now; one who has finished its routine steps aside to the point, among
    ``ASIDE_DIRECTIONS`` at ``ASIDE_M`` around it on the mesh, farthest from k's path, and stands there.
    """
    path = np.vstack([w.pos[k], w.paths[k][w.corner[k] :]])

    def clearance(points: np.ndarray) -> np.ndarray:
        return _to_segments(points, path[:-1], path[1:]) if len(path) > 1 else _length(points - w.pos[k])

    standing = np.flatnonzero(~moving)
    if not len(standing):
        return
    angles = np.arange(ASIDE_DIRECTIONS) * 2 * np.pi / ASIDE_DIRECTIONS
    ring = ASIDE_M * np.column_stack([np.cos(angles), np.sin(angles)])
    for j in standing[clearance(w.pos[standing]) < 2 * radius + 0.1]:
        if not w.arrived[j]:
            w.depart[j] = min(w.depart[j], t)
            w.dwell_until[j] = min(w.dwell_until[j], t)
            continue
        spots = w.pos[j] + ring
        spots = spots[mesh.contains(spots)]
        if not len(spots):
            continue
        spot = spots[int(np.argmax(clearance(spots)))]
        w.stops[j].append((spot, 0.0, True, None))
        w.leg[j] = len(w.stops[j]) - 1
        w.goal[j] = spot
        w.arrived[j] = False  # walking again; it keeps its arrival
        path_j = _plan(mesh, w.pos[j], spot)
        _set_path(w, j, path_j if path_j is not None else spot[None].copy())
        w.best[j] = _remaining(w, np.array([j]))[0]
        w.last_progress[j] = t


def _replan_around_standing(w: _Walkers, mesh: Navmesh, k: int, moving: np.ndarray, radius: float):
    """A new path for stalled pedestrian k that avoids everyone standing (Detour's temporary obstacles).

    Returns the path and why a later stall is final: the way is blocked, or the crowd is too dense.
    """
    standing = np.flatnonzero(~moving)
    if len(standing):
        carved = carve_discs(mesh, w.pos[standing], 2 * radius + REPLAN_CLEARANCE_M)
        res = carved.find_path(w.pos[k], w.goal[k], max_snap=MAX_SNAP_M, allow_partial=False)
        if res.status == "ok":
            return (res.points[1:] if len(res.points) > 1 else res.points), "too crowded"
    path = _plan(mesh, w.pos[k], w.goal[k])
    reason = "the way is blocked by pedestrians standing at their start or goal" if len(standing) else "too crowded"
    return (path if path is not None else w.paths[k][w.corner[k] :]), reason


def _queue(w: _Walkers, queues: Queues, moving: np.ndarray, t: float) -> None:
    """Ask for the passages ahead, grant them (:class:`Queues`); one granted its passage walks on from here."""
    ahead = [w.paths[k][w.corner[k] :] for k in range(len(w.pos))]
    for k in queues.update(w.pos, ahead, moving, t):
        w.best[k], w.last_progress[k] = _remaining(w, np.array([k]))[0], t


def _simulate(w: _Walkers, mesh: Navmesh, avoid: LocalAvoidance, cfg: CrowdConfig):
    """Run the crowd until everyone has finished or time is up: (xy (N, F, 2), yaw (N, F), speed (N, F)).

    F is the last frame simulated + 1 (at most ``cfg.max_duration_s`` · fps + 1).
    """
    n, frames = len(w.pos), int(cfg.max_duration_s * cfg.fps) + 1
    xy, yaw, speed = np.zeros((n, frames, 2)), np.zeros((n, frames)), np.zeros((n, frames))
    xy[:, 0], yaw[:, 0] = w.pos, w.heading
    turn = FACE_TURN_RATE / cfg.fps
    queues = Queues(find_passages(mesh, cfg.agent_radius_m), mesh, n) if cfg.queue_at_passages else None
    grouped = bool((w.leader >= 0).any())
    frame = 0
    while frame < frames - 1 and not w.arrived.all():
        frame += 1
        t = frame / cfg.fps
        if grouped:
            _hold_for_group(w, t)
        moving = walking(w.depart, w.arrived, w.yield_until, w.dwell_until, t)
        _wait_for_passers(w, moving, frame, cfg)
        w.face[moving] = np.nan  # it has left its object
        if queues is not None and frame % CHECK_EVERY == 0:
            _queue(w, queues, moving, t)
        _step_frame(w, mesh, avoid, moving, cfg, frame, queues)
        _check_progress(w, mesh, moving, t, cfg)
        if w.decide:
            _decide(w, mesh, moving, t, cfg.agent_radius_m)
        record_frame(w.pos, w.vel, w.smooth, w.heading, w.face, turn, xy, yaw, speed, frame)
    return xy[:, : frame + 1], yaw[:, : frame + 1], speed[:, : frame + 1]


def _jitter(intents: list[Intent], cfg: CrowdConfig, rng: np.random.Generator) -> np.ndarray:
    """(N, 2) start offsets breaking exact symmetry, each a function of (rng's first draw, pedestrian id) alone."""
    base = int(rng.integers(2**63))
    jitter = [np.random.default_rng([base, i.id]).uniform(-1.0, 1.0, 2) for i in intents]
    return np.array(jitter, dtype=np.float64).reshape(-1, 2) * cfg.start_jitter_m


def plan_crowd(
    intents: list[Intent],
    mesh: Navmesh,
    avoid: LocalAvoidance,
    cfg: CrowdConfig,
    rng: np.random.Generator,
    outlines: dict[str, np.ndarray] | None = None,
    radii: dict[int, float] | None = None,
) -> CrowdPlan:
    """Simulate all pedestrians jointly; those that cannot start are left out with a reason.

    Args:
        intents: the scene's pedestrians (start, goal, speed, departure).
        mesh: the navmesh of legal centres at ``cfg.agent_radius_m``.
        avoid: the local-avoidance model (:func:`song.pipeline.crowd.avoidance.make_avoidance`).
        cfg: crowd parameters.
        rng: seeded generator (start jitter).
        outlines: footprints (K, 2) of the scene's objects by id: someone standing at its start object
            or at a stop turns to face the nearest point of that object's outline (a person waits at a
            counter facing it); without one it keeps the heading it arrived with.
        radii: body radius by pedestrian id, m (:func:`song.pipeline.bodies.body_radii`), at most
            ``cfg.agent_radius_m`` (the navmesh's clearance from walls); missing ids take
            ``cfg.agent_radius_m``. Bodies keep clear of each other by their own radii.
    """
    jitter = _jitter(intents, cfg, rng)
    lead = _lead_in_frames(intents, cfg.fps)  # the simulation's clock starts at the earliest departure
    shift = lead / cfg.fps  # the scenario's t = 0 on the simulation's clock
    if lead:
        intents = [i.model_copy(update={"depart_time": i.depart_time + shift}) for i in intents]
        cfg = cfg.model_copy(update={"max_duration_s": cfg.max_duration_s + shift})
    kept = np.arange(len(intents))
    radius = np.array([_body_radius(radii, i.id, cfg) for i in intents], dtype=np.float64)
    status: dict[int, dict] = {}
    while len(kept):  # leaving one out can change another's start (overlaps), so check again
        w, failures = _start([intents[k] for k in kept], mesh, jitter[kept], outlines or {}, radius[kept])
        for k, reason in sorted(failures.items()):
            status[intents[kept[k]].id] = {
                "status": "removed",
                "reason": reason,
                "arrival_s": None,
                "skipped_stops": [],
            }
        kept = np.delete(kept, list(failures))
        if not failures:
            break
    if not len(kept):
        return CrowdPlan(
            np.zeros(0, np.int64), np.zeros((0, 1, 2)), np.zeros((0, 1)), np.zeros((0, 1)), cfg.fps, status
        )
    xy, yaw, speed = _simulate(w, mesh, avoid, cfg)
    decide: dict[tuple[int, int], tuple[float, np.ndarray]] = {}
    for _ in range(HINDSIGHT_PASSES if cfg.give_up_in_hindsight else 0):
        late = {
            key: at for key, at in _late_decisions(w, xy, mesh, cfg).items() if decide.get(key, (None,))[0] != at[0]
        }
        if not late:
            break
        decide |= late  # run again: each of them gives its stop up when its futile try began
        w, _ = _start([intents[k] for k in kept], mesh, jitter[kept], outlines or {}, radius[kept])
        w.decide = dict(decide)
        xy, yaw, speed = _simulate(w, mesh, avoid, cfg)
    for row, k in enumerate(kept):
        status[intents[k].id] = {**_outcome(w, row, cfg, shift), "body_radius_m": round(float(radius[k]), 6)}
    ids = np.array([intents[k].id for k in kept], dtype=np.int64)
    span = slice(min(lead, xy.shape[1] - 1), None)  # the scenario: from t = 0 on
    return CrowdPlan(ids, xy[:, span].copy(), yaw[:, span].copy(), speed[:, span].copy(), cfg.fps, status)


def _late_decisions(w: _Walkers, xy: np.ndarray, mesh: Navmesh, cfg: CrowdConfig) -> dict:
    """Stops given up long after the walker last got nearer: (pedestrian, routine stop) -> (when instead, s; where).

    ``where``: where it stood at that time in this run.

    Nearer: ``PROGRESS_M`` less path to the stop on the navmesh (a straight line would count a detour round
    a wall as no progress), from where it stood every ``HINDSIGHT_EVERY`` frames since it set off for the
    stop. The decision falls ``cfg.stall_time_s`` after that last progress: its first stall on the way.
    """
    late = {}
    for k, events in enumerate(w.given_up):
        for stop, where, began, when in events:
            frames = np.arange(int(np.ceil(began * cfg.fps)), int(when * cfg.fps) + 1, HINDSIGHT_EVERY)
            if len(frames) < 2:
                continue
            gap = np.array([mesh.find_path(xy[k, f], where, max_snap=MAX_SNAP_M, allow_partial=True).length
                            for f in frames])  # fmt: skip
            best = np.minimum.accumulate(gap)
            behind = np.flatnonzero(best > best[-1] + PROGRESS_M)  # before its last progress
            since = frames[behind[-1] + 1 if len(behind) else 0] / cfg.fps
            if when > since + cfg.stall_time_s + HINDSIGHT_SLACK_S:
                when = since + cfg.stall_time_s
                late[(k, stop)] = (when, xy[k, min(int(np.ceil(when * cfg.fps - 1e-9)), xy.shape[1] - 1)].copy())
    return late


def _body_radius(radii: dict[int, float] | None, ped_id: int, cfg: CrowdConfig) -> float:
    """Pedestrian ``ped_id``'s body radius: its own where given (never above the navmesh's), else the configured one."""
    if radii is None or ped_id not in radii:
        return cfg.agent_radius_m
    radius = float(radii[ped_id])
    if not 0.0 < radius <= cfg.agent_radius_m + 1e-9:
        raise ValueError(f"body radius {radius} m of pedestrian {ped_id} is not in (0, {cfg.agent_radius_m}]")
    return radius


def _outcome(w: _Walkers, k: int, cfg: CrowdConfig, shift: float) -> dict:
    """Pedestrian k's entry of the crowd status (times on the scenario's clock, ``shift`` s after the simulation's)."""
    if not np.isnan(w.gave_up[k]):
        when = f"{w.gave_up[k] - shift:.1f} s"
        if k in w.decided:
            why = f"its way stayed blocked (decided in hindsight at its first stall, {when})"
        else:
            why = f"stalled for {cfg.stall_time_s:g} s after replanning ({w.replanned[k]}) at {when}"
        reason = f"{why}; it stepped out of the way and stands there"
        return {"status": "gave_up", "reason": reason, "arrival_s": None, "skipped_stops": w.skipped[k],
                "gave_up_s": round(float(w.gave_up[k]) - shift, 4),
                "last_leg_s": round(float(w.given_up[k][-1][2]) - shift, 4)}  # fmt: skip
    if not np.isnan(w.arrival[k]):  # it finished its routine (it may be stepping aside for someone now)
        return {"status": "arrived", "reason": "", "arrival_s": round(float(w.arrival[k]) - shift, 4),
                "skipped_stops": w.skipped[k]}  # fmt: skip
    reason = f"did not arrive within {cfg.max_duration_s - shift:g} s"
    return {"status": "timeout", "reason": reason, "arrival_s": None, "skipped_stops": w.skipped[k]}


def _lead_in_frames(intents: list[Intent], fps: int) -> int:
    """Frames simulated before the scenario's t = 0: people who departed earlier are on their way at t = 0."""
    earliest = min((i.depart_time for i in intents), default=0.0)
    return int(np.ceil(-earliest * fps - 1e-9)) if earliest < 0 else 0
