"""SONG's crowds against real pedestrians: the statistics of song.pipeline.crowd.realism, one method for both.

    .venv/bin/python benchmarks/crowd_realism.py [--generated 30] [--avoidance orca social_force]
        [--speed-profile paper human] [--seeds 1] [--set SECTION.KEY=VALUE ...] [--markdown]

Runs the intents and crowd stages on the sample scenes (8 procedural venues + 3 ProcTHOR houses) and
``--generated`` more procedural scenes, for every avoidance model × speed profile asked for, and
computes on the same footing the real ETH and Hotel sequences (EWAP obsmat files in ../shared; skipped
with a reason when absent) and, as an indoor check, the Edinburgh Informatics Forum atrium (automatic
tracker, ~9 fps: its speeds are approximate and its pair distances unreliable). Also per
configuration: the closest centre distance at any frame (walking or standing, against 2r), the shares
of intents that reach their last stop, that complete their whole routine (no stop given up on the way)
and that are removed, the walking share among present pedestrians per second between 5 s and 55 s
(mean over scenes, and over the sample scenes alone: the target's set; the minimum second), the gap
between the body and the nearest wall or furniture over moving samples (median, p5, share under
0.15 m; from the scene's navmesh, conservative by up to a grid cell), the density on the walkable
area (the scene's navmesh; median over scenes) beside the density on the floor people covered (the
one measure the real recordings allow), the heading reversals per walking minute (zigzags on the 30 FPS
tracks, ``realism.heading_reversals``), the crowd stage's median seconds per scene, for walkers who
gave up how long they got no nearer their last stop before it (``give_up_*``), and the tortuosity of the
routes alone (``route_tortuosity_*``: each leg's shortest path walked at the walker's speed, nobody
else there). Prints JSON (and a markdown table with ``--markdown``).

The crowd is chaotic: a change that helps one seed can hurt the next. ``--seeds 1 2 … 12`` runs every
configuration once per run seed (``SongConfig.seed``; the scenes stay the same) and adds ``targets``:
per configuration and target of issue 25, in how many seeds it is met, with the figure's minimum,
median and maximum over the seeds. ``--set crowd.comfort_distance_m=1.05`` (repeatable, as ``song
--set``) runs every configuration with that setting, to measure a parameter beside the defaults.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, crowd_outcomes, dither_summary, emit, give_up_dither  # noqa: E402

from song.config import SongConfig, parse_assignments  # noqa: E402
from song.datasets.run import read_crowd, read_intents  # noqa: E402
from song.datasets.scenes import load_scene_package  # noqa: E402
from song.datasets.scenes.generate import VENUE_ORDER, generate_scene  # noqa: E402
from song.pipeline.chain import iter_run  # noqa: E402
from song.pipeline.crowd.avoidance import WallDistance  # noqa: E402
from song.pipeline.crowd.navmesh import load_navmesh  # noqa: E402
from song.pipeline.crowd.realism import (  # noqa: E402
    Track,
    crowd_statistics,
    density,
    heading_reversals,
    read_edinburgh_tracks,
    read_obsmat,
    stop_facing,
    tortuosity,
    wall_clearances,
)

REAL = ROOT.parent / "shared" / "reference" / "pedestrians"
SAMPLES = ROOT / "datasets" / "sample_scenes"


def _walking_share(tracks: list[Track]) -> np.ndarray:
    """(56,) share of present pedestrians walking (> 0.2 m/s) at each second 0..55 (NaN when nobody)."""
    out = np.full(56, np.nan)
    if not tracks:
        return out
    for second in range(56):
        walking = []
        for tr in tracks:
            k = np.searchsorted(tr.t, second)
            if 0 < k < len(tr.t):
                v = np.hypot(*(tr.xy[k] - tr.xy[k - 1])) / (tr.t[k] - tr.t[k - 1])
                walking.append(v > 0.2)
        if walking:
            out[second] = np.mean(walking)
    return out


def _wall_stats(gaps: np.ndarray) -> dict:
    """The body's gap to walls and furniture over moving samples: median, p5, share under 0.15 m."""
    if not len(gaps):
        return {}
    return {
        "wall_gap_median_m": round(float(np.median(gaps)), 3),
        "wall_gap_p5_m": round(float(np.percentile(gaps, 5)), 3),
        "wall_gap_below_0.15_share": round(float(np.mean(gaps < 0.15)), 4),
    }


# issue 25's targets: name → (the figure in a configuration's statistics, whether it is met, profiles it binds)
TARGETS = {
    "head-on p25 >= 0.9 m": (lambda s: s["passes"]["head_on"]["p25"], lambda v: v >= 0.9, ("paper", "human")),
    "head-on < 0.6 m <= 8 %": (lambda s: s["passes"]["head_on"]["below_0.6"], lambda v: v <= 0.08, ("paper", "human")),
    "crossing < 0.5 m <= 2 %": (
        lambda s: s["passes"]["crossing"]["below_0.5"],
        lambda v: v <= 0.02,
        ("paper", "human"),
    ),
    "pairs < 2 m passing < 0.6 m <= 20 %": (
        lambda s: s["passes"]["all"]["below_0.6"],
        lambda v: v <= 0.2,
        ("paper", "human"),
    ),
    "speed median 1.1-1.5 m/s": (lambda s: s["speed_median_mps"], lambda v: 1.1 <= v <= 1.5, ("human",)),
    "closest at any frame minus the two bodies' radii >= -1 cm": (
        lambda s: s["body_gap_min_m"] + 0.01,
        lambda v: v >= 0.0,
        ("paper", "human"),
    ),
    "last stop reached >= 95 %": (lambda s: s["arrived_share"], lambda v: v >= 0.95, ("paper", "human")),
    "samples' walking share >= 0.5 every second 5-55 s": (
        lambda s: s["walking_share_samples_5_55_min"],
        lambda v: v >= 0.5,
        ("paper", "human"),
    ),
    "crowd stage <= 0.5 s median per scene": (
        lambda s: s["crowd_s_median_per_scene"],
        lambda v: v <= 0.5,
        ("paper", "human"),
    ),
}


SPREAD = {"min": np.min, "median": np.median, "max": np.max}


def target_summary(runs: list[dict], profile: str) -> dict:
    """Per target binding ``profile``: in how many of ``runs`` (one per seed) it is met; the figure's range.

    A run without the figure (no head-on pass, no scene planned) counts as not meeting the target.
    """
    out = {}
    for name, (figure, met, profiles) in TARGETS.items():
        if profile not in profiles:
            continue
        values = [v for v in (_figure(figure, run) for run in runs) if v is not None]
        spread = {k: round(float(f(values)), 4) if values else None for k, f in SPREAD.items()}
        out[name] = {"met": sum(bool(met(v)) for v in values), "of": len(runs), **spread}
    return out


def _figure(figure, run: dict):
    """``figure(run)``, or None where the run has no such figure."""
    try:
        return figure(run)
    except (KeyError, TypeError):
        return None


def route_tracks(intents, mesh, fps: int) -> list[Track]:
    """Each intent's legs walked alone along the navmesh's shortest path at its own constant speed, one track per leg.

    What the crowd would walk with nobody else there and corners taken on the spot: the floor of the
    tortuosity its routes allow (a crowd rounds corners, so it can come a little under it).
    """
    out = []
    for i in intents:
        here = np.asarray(i.start_xy, dtype=np.float64)
        for leg in i.route():
            res = mesh.find_path(here, np.asarray(leg.goal_xy, dtype=np.float64), max_snap=0.5, allow_partial=True)
            points = res.points if len(res.points) else here[None]
            here = points[-1]
            along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
            if along[-1] < 1e-6:
                continue
            t = np.arange(0.0, along[-1] / i.speed, 1.0 / fps)
            xy = np.column_stack([np.interp(t * i.speed, along, points[:, k]) for k in range(2)])
            out.append(Track(t, xy))
    return out


def run_config(scenes: Path, avoidance: str, profile: str, work: Path, seed: int = 1, sets: dict | None = None) -> dict:
    sets = sets or {}
    config = SongConfig(
        **{k: v for k, v in sets.items() if k not in ("seed", "crowd", "intents")},
        seed=seed,
        crowd={**sets.get("crowd", {}), "avoidance": avoidance},
        intents={**sets.get("intents", {}), "speed_profile": profile},
    )
    run = work / f"{avoidance}-{profile}-{seed}"
    results = list(iter_run(scenes, run, config, ["intents", "crowd"], workers=2))
    seconds = [r.seconds.get("crowd", 0.0) for r in results if r.status == "ok"]
    tracks, closest, gap, shares, sample_shares, statuses, facing, walls = [], np.inf, np.inf, [], [], [], [], []
    radii: list[float] = []
    reversals, walking_minutes = 0, 0.0
    walkable: list[float] = []
    sizes: list[int] = []  # walking groups' sizes (1: alone), from the intents
    routes: list[np.ndarray] = []  # tortuosity of the shortest routes walked alone (the floor)
    dither: list[tuple[float, float]] = []  # walkers who gave up: no progress before it, s; walked then, m
    r = config.crowd.agent_radius_m
    for scene in sorted((run / "scenes").iterdir()):
        crowd = read_crowd(scene)
        status = json.loads((scene / "crowd_status.json").read_text())
        intents = read_intents(scene / "intents.json").intents
        statuses += status.values()
        groups = Counter(i.group if i.group is not None else -1 - i.id for i in intents)
        sizes += list(groups.values())
        if len(crowd.ids) == 0:
            continue
        objects = load_scene_package(scenes / scene.name).semantic_map.object_by_id()
        facing += stop_facing(crowd, intents, objects)
        scene_tracks = [Track(crowd.t, crowd.xy[k]) for k in range(len(crowd.ids))]
        tracks.append(scene_tracks)
        count, minutes = heading_reversals(scene_tracks)
        reversals, walking_minutes = reversals + count, walking_minutes + minutes
        mesh = load_navmesh(scene)
        field = WallDistance(mesh)
        routes.append(tortuosity(route_tracks(intents, mesh, crowd.fps)))
        dither += give_up_dither(crowd.xy, crowd.ids, status, intents, mesh, crowd.fps)
        walls.append(wall_clearances(scene_tracks, lambda xy, f=field: f.at(xy) - r))
        walkable.append(density(scene_tracks, mesh.area))
        shares.append(_walking_share(scene_tracks))
        if not scene.name.startswith("gen_"):
            sample_shares.append(shares[-1])
        body = np.array([status[str(int(i))].get("body_radius_m") or r for i in crowd.ids])
        radii += body.tolist()
        if len(crowd.ids) > 1:
            d = np.hypot(*(crowd.xy[:, None] - crowd.xy[None]).transpose(3, 0, 1, 2))
            d[np.arange(len(d)), np.arange(len(d))] = np.inf
            closest = min(closest, float(d.min()))
            gap = min(gap, float((d - (body[:, None] + body[None])[..., None]).min()))
    share = np.nanmean(np.stack(shares), axis=0)[5:56] if shares else np.zeros(0)
    sample = np.nanmean(np.stack(sample_shares), axis=0)[5:56] if sample_shares else np.zeros(0)
    stats = crowd_statistics(tracks)
    stats.update(
        {
            "closest_any_frame_m": round(closest, 4),
            "body_gap_min_m": round(gap, 4),  # closest two bodies ever come, less their radii
            "body_radius_m": {q: round(float(np.percentile(radii, q)), 3) for q in (0, 50, 100)} if radii else None,
            **crowd_outcomes(statuses),
            "walking_share_5_55_mean": round(float(np.mean(share)), 4) if len(share) else None,
            "walking_share_5_55_min": round(float(np.min(share)), 4) if len(share) else None,
            "walking_share_samples_5_55_mean": round(float(np.mean(sample)), 4) if len(sample) else None,
            "walking_share_samples_5_55_min": round(float(np.min(sample)), 4) if len(sample) else None,
            **_wall_stats(np.concatenate(walls) if walls else np.zeros(0)),
            "density_walkable_per_m2": round(float(np.median(walkable)), 4) if walkable else None,
            "heading_reversals_per_walking_min": round(reversals / walking_minutes, 2) if walking_minutes else None,
            "stops_facing_away_over_45deg": round(float(np.mean(np.asarray(facing) > 45.0)), 4) if facing else None,
            "stops_facing_error_median_deg": round(float(np.median(facing)), 2) if facing else None,
            "crowd_s_median_per_scene": round(float(np.median(seconds)), 3) if seconds else None,
            **dither_summary(dither),
            **_route_tortuosity(np.concatenate(routes) if routes else np.zeros(0)),
            "in_groups_share": round(sum(n for n in sizes if n > 1) / max(sum(sizes), 1), 4),
            "group_sizes": {str(n): sizes.count(n) for n in sorted(set(sizes))},
            "scenes": len(results),
            "failed_scenes": [x.scene_id for x in results if x.status != "ok"],
        }
    )
    return stats


def _route_tortuosity(samples: np.ndarray) -> dict:
    """Median and p95 of the routes' own tortuosity (:func:`route_tracks` through ``tortuosity``, every scene)."""
    if not len(samples):
        return {}
    return {
        "route_tortuosity_median": round(float(np.median(samples)), 4),
        "route_tortuosity_p95": round(float(np.percentile(samples, 95)), 4),
    }


def _density_cell(stats: dict) -> str:
    walkable = stats.get("density_walkable_per_m2")
    return f"{stats['density_covered_per_m2']}" + (f" ({walkable})" if walkable is not None else "")


def _give_up_cell(stats: dict) -> str:
    walkers = stats["give_up_walkers"]
    return f"{walkers} ({stats['give_up_no_progress_s_max']})" if walkers else "0"


def markdown(rows: dict[str, dict]) -> str:
    cols = [
        ("head-on p25, m", lambda s: s["passes"]["head_on"]["p25"]),
        ("head-on < 0.6 m", lambda s: s["passes"]["head_on"]["below_0.6"]),
        ("crossing < 0.5 m", lambda s: s["passes"]["crossing"]["below_0.5"]),
        ("pairs < 2 m passing < 0.6 m", lambda s: s["passes"]["all"]["below_0.6"]),
        ("speed median (p95), m/s", lambda s: f"{s['speed_median_mps']} ({s['speed_p95_mps']})"),
        ("standing share", lambda s: s["standing_share"]),
        ("tortuosity median (p95)", lambda s: f"{s['tortuosity_median']} ({s['tortuosity_p95']})"),
        ("the routes alone: tortuosity p95", lambda s: s["route_tortuosity_p95"]),
        (
            "accel RMS (steady walking: along / across), m/s²",
            lambda s: (
                f"{s['acceleration_rms_mps2']} ({s['acceleration_rms_steady_mps2']}: "
                f"{s.get('acceleration_rms_steady_along_mps2')} / {s.get('acceleration_rms_steady_across_mps2')})"
            ),
        ),
        ("heading reversals / walking min", lambda s: s["heading_reversals_per_walking_min"]),
        ("moving within 0.15 m of a wall", lambda s: s["wall_gap_below_0.15_share"]),
        ("density, /m² covered (walkable)", _density_cell),
        ("last stop / whole routine reached", lambda s: f"{s['arrived_share']} / {s['routine_complete_share']}"),
        ("gave up: walkers (s without progress, max)", _give_up_cell),
    ]
    lines = ["| set | " + " | ".join(c for c, _ in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for name, stats in rows.items():
        cells = []
        for _, get in cols:
            try:
                cells.append(str(get(stats)))
            except (KeyError, TypeError):
                cells.append("–")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def targets_markdown(targets: dict[str, dict]) -> str:
    lines = ["| configuration | target | met in seeds | min / median / max |", "|---|---|---|---|"]
    for config, rows in targets.items():
        for name, t in rows.items():
            lines.append(f"| {config} | {name} | {t['met']} of {t['of']} | {t['min']} / {t['median']} / {t['max']} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--generated", type=int, default=30)
    parser.add_argument("--avoidance", nargs="+", default=["orca", "social_force"])
    parser.add_argument("--speed-profile", nargs="+", default=["paper", "human"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1], help="run seeds (SongConfig.seed)")
    parser.add_argument(
        "--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="config override (as `song --set`)"
    )
    parser.add_argument("--markdown", action="store_true")
    args = parser.parse_args()
    sets = parse_assignments(args.set)
    work = Path(tempfile.mkdtemp(prefix="song-crowd-realism-"))
    rows: dict[str, dict] = {}
    targets: dict[str, dict] = {}
    try:
        scenes = work / "scenes"
        shutil.copytree(SAMPLES, scenes, ignore=shutil.ignore_patterns("*.md", "*.txt"))
        if args.generated:
            for k in range(args.generated):  # ids distinct from the sample scenes'
                venue = VENUE_ORDER[k % len(VENUE_ORDER)]
                generate_scene(f"gen_{venue}_{k:04d}", venue, 1234, scenes, splat=False)
        for avoidance in args.avoidance:
            for profile in args.speed_profile:
                runs = []
                for seed in args.seeds:
                    start = time.perf_counter()
                    stats = run_config(scenes, avoidance, profile, work, seed, sets)
                    stats["wall_s"] = round(time.perf_counter() - start, 1)
                    name = f"SONG {avoidance} / {profile}" + (f" / seed {seed}" if len(args.seeds) > 1 else "")
                    rows[name] = stats
                    runs.append(stats)
                targets[f"SONG {avoidance} / {profile}"] = target_summary(runs, profile)
        for name in ("eth", "hotel"):
            path = REAL / f"ewap_seq_{name}_obsmat.txt"
            rows[f"real {name.upper()}"] = (
                crowd_statistics(read_obsmat(path)) if path.is_file() else {"skipped": f"{path} is absent"}
            )
        path = REAL / "edinburgh_forum_tracks.01Aug.txt"  # indoor; speeds approximate, pair distances unreliable
        rows["real Edinburgh Forum (indoor, approx.)"] = (
            crowd_statistics(read_edinburgh_tracks(path)) if path.is_file() else {"skipped": f"{path} is absent"}
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    emit({**rows, "targets": targets})
    if args.markdown:
        print(markdown({k: v for k, v in rows.items() if "skipped" not in v}))  # noqa: T201
        print(targets_markdown(targets))  # noqa: T201


if __name__ == "__main__":
    main()
