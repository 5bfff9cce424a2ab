"""Crowd statistics computed one way on any trajectories (SONG's crowds and real annotated pedestrians).

Tracks are resampled to a common rate (2.5 Hz, the rate of the EWAP annotations) before anything is
measured. With ``MOVING_MPS`` = 0.2 m/s as the walking threshold:

- **speed**: median, p5 and p95 of the speed over moving samples;
- **standing share**: standing samples over all samples of present pedestrians, and within each
  pedestrian's active window (its first to last moving sample);
- **passes**: for every pair present together while both move, the closest approach of their centres
  (refined between samples: the minimum of the linearly interpolated distance), if it is under
  ``INTERACTION_M`` (2 m) -- classified by the angle between their velocities at that moment:
  head-on (> 135°), crossing, same direction (< 45°); p5/p25/median and the shares below 0.5, 0.6 and
  0.8 m per class, and the share of all such pairs passing closer than 0.6 m;
- **tortuosity**: path length over displacement in 5 s windows of walking (displacement ≥ 1 m), median and p95;
- **acceleration RMS** over moving samples (finite differences of the resampled velocity), and over
  steady walking alone (moving samples at least ``STEADY_S`` from any standing one: no setting off or
  stopping, which SONG's walkers do at every stop of their routines and the outdoor recordings' passers-by
  rarely do in view), that one split along the velocity (speed changes) and across it (turning);
- **density**: the mean number of pedestrians present per m², over the samples at which anyone is,
  on the floor the recording's people covered (:func:`covered_area`: the 0.5 m cells holding any of
  their samples; the real recordings give no walkable area), and, where it is known, on the walkable
  area (:func:`density`).

SONG's crowds also know what people stand at and what walls they pass: :func:`stop_facing` measures
how far from their object pedestrians face while standing at it, and :func:`wall_clearances` how
close walkers come to walls and furniture (no real reference for either: the annotations have no
objects, and no walls indoors), and :func:`heading_reversals` how often a walker's heading swings
one way and straight back at the crowd's own frame rate (the 2.5 Hz annotations cannot show it).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from song.geometry.outline import nearest_on_outline
from song.geometry.rotations import wrap_angle

RATE_HZ = 2.5
MOVING_MPS = 0.2
INTERACTION_M = 2.0
HEAD_ON_DEG, SAME_DIR_DEG = 135.0, 45.0
WINDOW_S = 5.0
STEADY_S = 2.0  # steady walking: this far in time from any standing sample (setting off takes 1–2 s)
COVER_CELL_M = 0.5
SWING_DEG, SWING_FRAMES, REVERSAL_FRAMES = 20.0, 3, 12  # a swing: > 20° in 3 frames; back within 12 (0.4 s at 30 FPS)


@dataclass(frozen=True)
class Track:
    """One pedestrian: times (T,) s, positions (T, 2) m."""

    t: np.ndarray
    xy: np.ndarray


def resample(tracks: list[Track], rate_hz: float = RATE_HZ) -> list[Track]:
    """Tracks on a common clock (multiples of 1/rate), linearly interpolated; shorter than 2 samples dropped."""
    out = []
    for track in tracks:
        t0, t1 = np.ceil(track.t[0] * rate_hz), np.floor(track.t[-1] * rate_hz)
        grid = np.arange(t0, t1 + 1) / rate_hz
        if len(grid) >= 2:
            xy = np.column_stack([np.interp(grid, track.t, track.xy[:, k]) for k in range(2)])
            out.append(Track(grid, xy))
    return out


def _rms(parts: list[np.ndarray]) -> float | None:
    values = np.concatenate(parts) if parts else np.zeros(0)
    return round(float(np.sqrt(np.mean(values**2))), 3) if len(values) else None


def _velocity(track: Track) -> np.ndarray:
    return np.gradient(track.xy, track.t, axis=0) if len(track.t) > 1 else np.zeros_like(track.xy)


def _closest(p: np.ndarray, q: np.ndarray) -> tuple[float, int, float]:
    """Closest approach of two synchronised paths (K, 2), refined on each segment: (distance, index, fraction)."""
    d0 = p[:-1] - q[:-1]
    dd = (p[1:] - q[1:]) - d0
    denom = (dd * dd).sum(axis=1)
    s = np.clip(-(d0 * dd).sum(axis=1) / np.where(denom > 0, denom, 1.0), 0.0, 1.0)
    gap = np.hypot(*(d0 + s[:, None] * dd).T)
    k = int(np.argmin(gap))
    return float(gap[k]), k, float(s[k])


def pass_distances(tracks: list[Track]) -> dict[str, np.ndarray]:
    """Closest approaches (m) of interacting pairs by class: ``head_on``, ``crossing``, ``same``, ``all``."""
    velocities = [_velocity(track) for track in tracks]
    keys = [np.round(track.t * RATE_HZ).astype(np.int64) for track in tracks]
    out: dict[str, list[float]] = {"head_on": [], "crossing": [], "same": [], "all": []}
    for i in range(len(tracks)):
        for j in range(i + 1, len(tracks)):
            common, a, b = np.intersect1d(keys[i], keys[j], return_indices=True)
            if len(common) < 2:
                continue
            vi, vj = velocities[i][a], velocities[j][b]
            moving = (np.hypot(*vi.T) > MOVING_MPS) & (np.hypot(*vj.T) > MOVING_MPS)
            if moving.sum() < 2:
                continue
            keep = np.flatnonzero(moving)
            runs = np.split(keep, np.flatnonzero(np.diff(keep) > 1) + 1)  # contiguous stretches of both moving
            best = (np.inf, None)
            for run in runs:
                if len(run) >= 2:
                    gap, k, _ = _closest(tracks[i].xy[a][run], tracks[j].xy[b][run])
                    if gap < best[0]:
                        best = (gap, run[k])
            gap, at = best
            if at is None or gap >= INTERACTION_M:
                continue
            cos = float(np.dot(vi[at], vj[at]) / max(np.hypot(*vi[at]) * np.hypot(*vj[at]), 1e-12))
            angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
            kind = "head_on" if angle > HEAD_ON_DEG else "same" if angle < SAME_DIR_DEG else "crossing"
            out[kind].append(gap)
            out["all"].append(gap)
    return {k: np.asarray(v) for k, v in out.items()}


def _summary(values: np.ndarray) -> dict[str, float | int | None]:
    if not len(values):
        return {
            "n": 0,
            "p5": None,
            "p25": None,
            "median": None,
            "below_0.5": None,
            "below_0.6": None,
            "below_0.8": None,
        }
    return {
        "n": int(len(values)),
        "p5": round(float(np.percentile(values, 5)), 3),
        "p25": round(float(np.percentile(values, 25)), 3),
        "median": round(float(np.median(values)), 3),
        **{f"below_{b}": round(float(np.mean(values < b)), 4) for b in (0.5, 0.6, 0.8)},
    }


def _window_tortuosity(track: Track, moving: np.ndarray) -> list[float]:
    """Path length over displacement in the track's successive ``WINDOW_S`` windows of walking (displacement ≥ 1 m)."""
    out = []
    span = int(round(WINDOW_S * RATE_HZ))
    for start in range(0, len(track.t) - span, span):
        seg = track.xy[start : start + span + 1]
        if moving[start : start + span + 1].all():
            disp = float(np.hypot(*(seg[-1] - seg[0])))
            if disp >= 1.0:
                out.append(float(np.hypot(*np.diff(seg, axis=0).T).sum()) / disp)
    return out


def tortuosity(tracks: list[Track]) -> np.ndarray:
    """The tortuosity samples of :func:`crowd_statistics` (resampled to 2.5 Hz, walking windows only)."""
    out: list[float] = []
    for track in resample(tracks):
        out += _window_tortuosity(track, np.hypot(*_velocity(track).T) > MOVING_MPS)
    return np.asarray(out)


def crowd_statistics(groups: list[list[Track]] | list[Track], walkable_m2: float | None = None) -> dict:
    """Every statistic of the module docstring, resampled here to 2.5 Hz.

    Args:
        groups: tracks of one scene or recording, or a list of such groups (pairs are only formed within
            a group: different scenes share a clock but not a floor).
        walkable_m2: the walkable area, for the density (one group only).
    """
    if groups and isinstance(groups[0], Track):
        groups = [groups]
    groups = [resample(group) for group in groups]
    tracks = [track for group in groups for track in group]
    speeds, standing, active_standing, active_total, windows, accel, steady = [], 0, 0, 0, [], [], []
    along, across = [], []  # steady acceleration along the velocity (speed changes) and across it (turning)
    total = 0
    for track in tracks:
        v = _velocity(track)
        s = np.hypot(*v.T)
        moving = s > MOVING_MPS
        speeds.append(s[moving])
        total += len(s)
        standing += int((~moving).sum())
        if moving.any():
            lo, hi = np.flatnonzero(moving)[[0, -1]]
            active_total += hi - lo + 1
            active_standing += int((~moving[lo : hi + 1]).sum())
            a = np.gradient(v, track.t, axis=0)
            accel.append(np.hypot(*a[moving].T))
            reach = int(round(STEADY_S * RATE_HZ))
            window = np.convolve((~moving).astype(int), np.ones(2 * reach + 1, int))  # length n + 2·reach
            near_stop = window[reach : reach + len(moving)] > 0
            steady.append(np.hypot(*a[moving & ~near_stop].T))
            keep = moving & ~near_stop
            unit = v[keep] / s[keep, None]
            along.append((a[keep] * unit).sum(axis=1))
            across.append(a[keep, 1] * unit[:, 0] - a[keep, 0] * unit[:, 1])
        windows += _window_tortuosity(track, moving)
    speed = np.concatenate(speeds) if speeds else np.zeros(0)
    per_group = [pass_distances(group) for group in groups]
    passes = {
        kind: np.concatenate([p[kind] for p in per_group] + [np.zeros(0)])
        for kind in ("head_on", "crossing", "same", "all")
    }
    stats = {
        "pedestrians": len(tracks),
        "speed_median_mps": round(float(np.median(speed)), 3) if len(speed) else None,
        "speed_p5_mps": round(float(np.percentile(speed, 5)), 3) if len(speed) else None,
        "speed_p95_mps": round(float(np.percentile(speed, 95)), 3) if len(speed) else None,
        "standing_share": round(standing / max(total, 1), 4),
        "standing_share_active": round(active_standing / max(active_total, 1), 4),
        "tortuosity_median": round(float(np.median(windows)), 4) if windows else None,
        "tortuosity_p95": round(float(np.percentile(windows, 95)), 4) if windows else None,
        "acceleration_rms_mps2": _rms(accel),
        "acceleration_rms_steady_mps2": _rms(steady),
        "acceleration_rms_steady_along_mps2": _rms(along),
        "acceleration_rms_steady_across_mps2": _rms(across),
        "passes": {kind: _summary(values) for kind, values in passes.items()},
    }
    covered = [density(group, covered_area(group)) for group in groups if group]
    stats["density_covered_per_m2"] = round(float(np.median(covered)), 4) if covered else None
    if walkable_m2:
        stats["density_per_m2"] = round(density(tracks, walkable_m2), 4)
    return stats


def covered_area(tracks: list[Track], cell_m: float = COVER_CELL_M) -> float:
    """The floor the pedestrians covered, m²: the ``cell_m`` grid cells holding any of their 2.5 Hz samples."""
    cells = [np.floor(track.xy / cell_m).astype(np.int64) for track in resample(tracks)]
    return float(len(np.unique(np.concatenate(cells), axis=0))) * cell_m**2 if cells else 0.0


def density(tracks: list[Track], area_m2: float) -> float:
    """Mean number of pedestrians present per m² of ``area_m2``, over the 2.5 Hz samples at which anyone is."""
    ticks = [np.round(track.t * RATE_HZ).astype(np.int64) for track in resample(tracks)]
    if not ticks or area_m2 <= 0.0:
        return 0.0
    ticks = np.concatenate(ticks)
    present = np.bincount(ticks - ticks.min())
    return float(present[present > 0].mean()) / area_m2


def wall_clearances(tracks: list[Track], clearance_at) -> np.ndarray:
    """The body's gap to the nearest wall or furniture at every moving sample (2.5 Hz), m.

    Args:
        tracks: one scene's pedestrians (resampled here).
        clearance_at: (M, 2) positions -> (M,) gap between the body and the nearest obstacle, m.
    """
    gaps = [np.zeros(0)]
    for track in resample(tracks):
        moving = np.hypot(*_velocity(track).T) > MOVING_MPS
        if moving.any():
            gaps.append(np.asarray(clearance_at(track.xy[moving]), dtype=np.float64))
    return np.concatenate(gaps)


def heading_reversals(tracks: list[Track]) -> tuple[int, float]:
    """Heading reversals on full-rate tracks: ``(count, walking minutes)``.

    A swing is a turn of the walking direction by more than ``SWING_DEG`` within ``SWING_FRAMES``
    frames, both ends moving (> ``MOVING_MPS``); a reversal is a swing followed within
    ``REVERSAL_FRAMES`` frames by one the other way (at 30 FPS: 20° in 0.1 s and back within 0.4 s, a
    zigzag no walker makes on purpose). Tracks are taken as they are (not resampled): the swings last
    a few frames. Walking minutes count the moving frames.
    """
    count, minutes = 0, 0.0
    for track in tracks:
        if len(track.t) < SWING_FRAMES + 2:
            continue
        dt = np.diff(track.t)
        v = np.diff(track.xy, axis=0) / dt[:, None]
        moving = np.hypot(*v.T) > MOVING_MPS
        minutes += float(dt[moving].sum()) / 60.0
        heading = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
        turn = heading[SWING_FRAMES:] - heading[:-SWING_FRAMES]
        both = moving[SWING_FRAMES:] & moving[:-SWING_FRAMES]
        swing = np.where(both & (np.abs(turn) > np.radians(SWING_DEG)), np.sign(turn), 0.0)
        last, side = -REVERSAL_FRAMES - 1, 0.0
        for i in np.flatnonzero(swing):
            if side and swing[i] == -side and i - last <= REVERSAL_FRAMES:
                count += 1
            last, side = i, swing[i]
    return count, minutes


def read_obsmat(path: str | Path) -> list[Track]:
    """EWAP ``obsmat.txt`` (frame, id, x, z, y, vx, vz, vy; 2.5 Hz annotations) as tracks on the ground plane.

    The annotation step is 0.4 s whatever the video frame numbering (every 6 frames at 15 fps for ETH,
    every 10 at 25 fps for Hotel), so times are taken from the annotation order within each frame step.
    """
    data = np.loadtxt(path)
    frames = np.unique(data[:, 0])
    step = np.median(np.diff(frames))
    tracks = []
    for ped in np.unique(data[:, 1]):
        rows = data[data[:, 1] == ped]
        rows = rows[np.argsort(rows[:, 0])]
        tracks.append(Track(rows[:, 0] / step / RATE_HZ, rows[:, [2, 4]]))
    return tracks


EDINBURGH_M_PER_PX = 0.0247  # the Forum camera's floor scale (the dataset's README: 24.7 mm per pixel)
EDINBURGH_FPS = 9.0  # "about 9 frames per second" (the dataset's README; the rate varies, so speeds are approximate)


def read_edinburgh_tracks(path: str | Path) -> list[Track]:
    """Edinburgh Informatics Forum tracks (``TRACK.Rn=[[x y frame];...];``, image pixels) on the floor, m.

    An indoor atrium seen from above by an automatic tracker: positions are ``EDINBURGH_M_PER_PX`` per
    pixel and times ``frame / EDINBURGH_FPS``, so speeds carry the capture rate's error (it varies around
    9 fps) and the tracker's jitter; pair distances are unreliable (fragmented, duplicated tracks).
    """
    text = Path(path).read_text()
    tracks = []
    for body in re.findall(r"TRACK\.R\d+=\[(.*?)\]\];", text, re.S):
        points = np.array([[float(v) for v in p.split()] for p in re.findall(r"\[([^\[\]]+)", body)])
        points = points[np.argsort(points[:, 2], kind="stable")]
        points = points[np.concatenate([[True], np.diff(points[:, 2]) > 0])]  # one point per frame
        if len(points) >= 2:
            tracks.append(Track(points[:, 2] / EDINBURGH_FPS, points[:, :2] * EDINBURGH_M_PER_PX))
    return tracks


def stop_facing(crowd, intents: list, objects: dict, settle_s: float = 2.0, min_stay_s: float = 4.0) -> list[float]:
    """How far (deg) from its object each pedestrian faces while standing at it, one value per stay.

    A stay: at least ``min_stay_s`` standing without a break (< 0.01 m/s) within 0.5 m of an intent's
    start before it first moves, or within 0.3 m of a leg's goal (someone held up in a jam beside the
    spot later, or stepping aside near its start, is not staying there);
    measured after its first ``settle_s`` (a turn on the spot) as the median |yaw − direction to the
    nearest point of the object's outline|.

    Args:
        crowd: the scene's crowd table (:func:`song.datasets.run.read_crowd`).
        intents: the scene's intents (``start_object``, ``start_xy``, ``route()``).
        objects: scene objects by id (``footprint``).
        settle_s: seconds of each stay left out at its start, s.
        min_stay_s: shorter stays are not measured, s.
    """
    by_id = {i.id: i for i in intents}
    out = []
    for k, pid in enumerate(crowd.ids):
        intent = by_id[int(pid)]
        stays = [(intent.start_object, intent.start_xy, 0.5)] + [
            (g.goal_object, g.goal_xy, 0.3) for g in intent.route()
        ]
        standing = crowd.speed[k] < 0.01
        departed = np.cumsum(~standing) > 0  # from its first move on
        for n, (oid, spot, near) in enumerate(stays):
            if oid not in objects:
                continue
            staying = standing & ~departed if n == 0 else standing  # n == 0: its start
            at = np.flatnonzero((np.hypot(*(crowd.xy[k] - np.asarray(spot)).T) < near) & staying)
            for frames in np.split(at, np.flatnonzero(np.diff(at) > 1) + 1):  # each unbroken stay
                if len(frames) < min_stay_s * crowd.fps:
                    continue
                settled = frames[frames >= frames[0] + settle_s * crowd.fps]
                p = crowd.xy[k, settled].mean(axis=0)
                q = nearest_on_outline(np.asarray(objects[oid].footprint), p[None])[0][0]
                want = np.arctan2(q[1] - p[1], q[0] - p[0])
                miss = np.abs(wrap_angle(crowd.yaw[k, settled] - want))
                out.append(float(np.degrees(np.median(miss))))
    return out
