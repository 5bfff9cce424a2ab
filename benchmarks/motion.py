"""Motion quality and speed over synthetic plans and every pedestrian of existing crowd runs (JSON).

.venv/bin/python benchmarks/motion.py [--quick] [--runs RUN ...] [--figure PATH]

Per pedestrian: procedural gait + the full post-processing (align, resample, smooth, contacts, foot
locking), then the issue's figures (``song/pipeline/motion/quality.py``). CPU seconds are process
time of generation + post-processing, reported per pedestrian-minute of motion. ``--figure`` writes a
PNG: a strip of stick-figure poses over one gait cycle (side and top views) and the foot heights.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import MotionConfig  # noqa: E402
from song.pipeline.motion import ProceduralGait, read_trajectories  # noqa: E402
from song.pipeline.motion.postprocess import postprocess  # noqa: E402
from song.pipeline.motion.quality import (  # noqa: E402
    CADENCE_AT_1_3_SPM,
    FEET_CLASH_M,
    HEADING_SEGMENTS,
    NORMATIVE,
    feet_gap,
    gait_cycle_figures,
    heading_leads,
    motion_quality,
)
from song.pipeline.motion.synthetic import (  # noqa: E402
    steady_walk,
    synthetic_trajectories,
    trajectory_from_profiles,
)
from song.util import derive_seed  # noqa: E402

TARGETS = {
    "foot_skating_ratio": ("max", 0.02),
    "penetration_p99_m": ("max", 0.01),
    "contact_float_max_m": ("max", 0.02),
    "root_error_mean_m": ("max", 0.02),
    "root_error_max_m": ("max", 0.05),
    "cadence_error_median": ("max", 0.10),
    "knee_flexion_min_deg": ("min", 0.0),
    "elbow_flexion_min_deg": ("min", 0.0),
    "cpu_s_per_ped_minute": ("max", 0.2),
}


def _measure(traj, seed: int, cfg: MotionConfig) -> tuple[dict, float, object]:
    start = time.process_time()
    raw = ProceduralGait(cfg).generate([traj], [""], [seed])[0]
    final, _ = postprocess(
        raw, traj, cfg.smoothing_sigma_frames, cfg.contact_height_m, cfg.contact_speed_mps, cfg.lock_blend_frames
    )
    cpu = time.process_time() - start
    quality = motion_quality(
        final.joints,
        final.local_quats,
        final.rest_joints,
        final.contacts,
        final.t,
        traj.xy,
        traj.speed,
        raw.info["walk_ratio_m_s"],
        cfg.min_cadence_spm,
    )
    return quality, cpu, final


SWEEP_MPS = (0.6, 0.8, 1.0, 1.2, 1.4, 1.6)
NORMATIVE_SPEEDS = (1.0, 1.4)  # the joint-angle ranges hold at these speeds (walk ratio: the whole sweep)


def normative(cfg: MotionConfig, seeds: int = 10) -> dict:
    """Gait-cycle figures of straight steady walks per speed (median over seeds) against normative ranges."""
    per_speed = {}
    for v in SWEEP_MPS:
        rows = []
        for seed in range(seeds):
            raw = ProceduralGait(cfg).generate([steady_walk(v)], [""], [seed])[0]
            final, _ = postprocess(
                raw, steady_walk(v), cfg.smoothing_sigma_frames, cfg.contact_height_m, cfg.contact_speed_mps,
                cfg.lock_blend_frames,
            )  # fmt: skip
            rows.append(
                gait_cycle_figures(final.local_quats, final.contacts, final.t, steady_walk(v).speed, final.joints)
            )
        per_speed[f"{v:.1f}"] = {k: round(float(np.median([r[k] for r in rows])), 3) for k in rows[0]}
    checks = {}
    for key, (lo, hi) in NORMATIVE.items():
        speeds = SWEEP_MPS[1:] if key == "walk_ratio_m_s" else NORMATIVE_SPEEDS
        values = [per_speed[f"{v:.1f}"][key] for v in speeds]
        checks[key] = {"range": [lo, hi], "speeds": list(speeds), "values": values,
                       "ok": all(lo <= x <= hi for x in values)}  # fmt: skip
    cadence = float(np.interp(1.3, SWEEP_MPS, [per_speed[f"{v:.1f}"]["cadence_spm"] for v in SWEEP_MPS]))
    checks["cadence_at_1.3_spm"] = {"range": list(CADENCE_AT_1_3_SPM), "values": [round(cadence, 1)],
                                    "ok": CADENCE_AT_1_3_SPM[0] <= cadence <= CADENCE_AT_1_3_SPM[1]}  # fmt: skip
    anti = [per_speed[f"{v:.1f}"]["arm_hip_correlation"] for v in NORMATIVE_SPEEDS]
    checks["arm_hip_correlation"] = {"range": [-1.0, -0.5], "speeds": list(NORMATIVE_SPEEDS), "values": anti,
                                     "ok": all(x <= -0.5 for x in anti)}  # fmt: skip
    gap = turn_sweep(cfg)
    checks["feet_gap_min_m"] = {"range": [FEET_CLASH_M, None], "speeds": list(TURN_SPEEDS),
                                "values": [gap], "ok": gap >= FEET_CLASH_M}  # fmt: skip
    return {"per_speed": per_speed, "checks": checks}


TURN_DEG = (45, 90, 135, 180)
TURN_SPEEDS = (0.5, 1.0, 1.4)
TURN_RATE = 1.5  # rad/s


def turn_sweep(cfg: MotionConfig, seeds: int = 3) -> float:
    """Smallest distance between the feet's centre lines over walking turns of 45-180° at 1.5 rad/s."""
    n = 300
    smallest = np.inf
    for deg in TURN_DEG:
        frames = int(round(30 * np.radians(deg) / TURN_RATE))
        yaw_rate = np.zeros(n)
        yaw_rate[120 : 120 + frames] = np.radians(deg) / (frames / 30.0)
        for v in TURN_SPEEDS:
            traj = trajectory_from_profiles(0, np.full(n, v), yaw_rate)
            for seed in range(seeds):
                _, _, final = _measure(traj, seed, cfg)
                smallest = min(smallest, float(feet_gap(final.joints).min()))
    return round(smallest, 4)


def normative_table(result: dict) -> str:
    """Markdown: each figure against its normative range."""
    lines = ["| figure | normative | ours | ok |", "|---|---|---|---|"]
    for key, check in result["checks"].items():
        lo, hi = check["range"]
        where = f" at {', '.join(str(v) for v in check.get('speeds', [1.3]))} m/s"
        values = " / ".join(f"{v:g}" for v in check["values"])
        span = f"≥ {lo:g}" if hi is None else f"{lo:g}–{hi:g}"
        lines.append(f"| {key}{where} | {span} | {values} | {'✓' if check['ok'] else '✗'} |")
    return "\n".join(lines) + "\n"


def _summary(rows: list[dict]) -> dict:
    out = {}
    for key in rows[0]:
        values = np.array([row[key] for row in rows], dtype=np.float64)
        out[key] = {
            "mean": round(float(values.mean()), 5),
            "max": round(float(values.max()), 5),
            "min": round(float(values.min()), 5),
        }
    return out


# Approximate normative means of healthy adults at natural cadence, read from the published curves every
# 10 % of the gait cycle (Winter 1991, Fig. 2.19; Perry & Burnfield 2010, ch. 7-8): a visual reference only.
NORMATIVE_CYCLE_PCT = np.arange(0, 101, 10)
NORMATIVE_KNEE_DEG = np.array([5, 18, 15, 8, 5, 10, 37, 60, 48, 20, 5])
NORMATIVE_HIP_DEG = np.array([30, 25, 15, 5, -3, -10, -5, 12, 25, 32, 30])


def _angle_panel(ax, motion, start: int, end: int) -> None:
    """Our left knee and hip flexion over one cycle beside the normative means."""
    from song.geometry.rotations import quat_to_axis_angle
    from song.geometry.skeleton import JOINT_INDEX

    aa = np.degrees(quat_to_axis_angle(motion.local_quats[start : end + 1]))
    pct = np.linspace(0, 100, end - start + 1)
    ax.plot(pct, aa[:, JOINT_INDEX["left_knee"], 1], color="tab:red", label="knee flexion (ours)")
    ax.plot(pct, -aa[:, JOINT_INDEX["left_hip"], 1], color="tab:green", label="hip flexion (ours)")
    ax.plot(NORMATIVE_CYCLE_PCT, NORMATIVE_KNEE_DEG, "o--", color="tab:red", alpha=0.5, label="knee, normative")
    ax.plot(NORMATIVE_CYCLE_PCT, NORMATIVE_HIP_DEG, "o--", color="tab:green", alpha=0.5, label="hip, normative")
    ax.set_xlabel("% of the gait cycle (left heel strike to left heel strike)")
    ax.set_ylabel("degrees")
    ax.set_title("sagittal joint angles at 1.0 m/s against normative means (Winter 1991; Perry & Burnfield 2010)")
    ax.legend(ncol=4, fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)


def figure(path: Path, cfg: MotionConfig) -> None:
    """Stick figures over one gait cycle (side, top) and the foot / pelvis heights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from song.geometry.skeleton import PARENTS

    traj = synthetic_trajectories(8.0)["straight_1.0"]
    _, _, motion = _measure(traj, 3, cfg)
    joints, contacts, t = motion.joints, motion.contacts, motion.t
    onsets = np.flatnonzero(contacts[1:, 0] & ~contacts[:-1, 0]) + 1
    start, end = onsets[2], onsets[3]
    frames = np.linspace(start, end, 9).round().astype(int)
    left = {1, 4, 7, 10, 13, 16, 18, 20, 22}
    right = {2, 5, 8, 11, 14, 17, 19, 21, 23}
    fig, axes = plt.subplots(4, 1, figsize=(13, 12), gridspec_kw={"height_ratios": [2.2, 1, 1.3, 1.5]})
    for k, f in enumerate(frames):
        pose = joints[f] - np.array([joints[f, 0, 0] - 0.75 * k, joints[f, 0, 1], 0.0])
        for j in range(1, 24):
            colour = "tab:red" if j in left else "tab:blue" if j in right else "k"
            p = PARENTS[j]
            axes[0].plot([pose[j, 0], pose[p, 0]], [pose[j, 2], pose[p, 2]], color=colour, lw=2)
            axes[1].plot([pose[j, 0], pose[p, 0]], [pose[j, 1], pose[p, 1]], color=colour, lw=1.5)
        axes[0].text(0.75 * k, -0.12, f"{100 * (f - start) / (end - start):.0f}%", ha="center", fontsize=8)
    axes[0].set_title("one gait cycle at 1.0 m/s (side view; red = left, blue = right; % of the cycle)")
    axes[1].set_title("top view")
    for ax in axes[:2]:
        ax.set_aspect("equal")
        ax.axis("off")
    axes[0].axhline(0.0, color="0.7", lw=0.8)
    window = (t >= t[start] - 1.0) & (t <= t[end] + 1.0)
    for side, (toe, ankle, colour) in enumerate(((10, 7, "tab:red"), (11, 8, "tab:blue"))):
        axes[2].plot(t[window], joints[window, toe, 2], color=colour, label=f"{'left' if side == 0 else 'right'} ball")
        axes[2].plot(t[window], joints[window, ankle, 2], color=colour, ls="--", lw=1, label="ankle")
        axes[2].fill_between(t[window], 0, 0.02 * contacts[window, side], color=colour, alpha=0.25, step="mid")
    axes[2].axhline(0.05, color="0.5", ls=":", lw=1, label="5 cm (skating height)")
    axes[2].set_xlabel("time (s)")
    axes[2].set_ylabel("height (m)")
    axes[2].set_title("foot heights (shaded: detected contact)")
    axes[2].legend(ncol=5, fontsize=8, loc="upper right")
    _angle_panel(axes[3], motion, start, end)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="synthetic plans + one crowd scene")
    parser.add_argument("--runs", type=Path, nargs="*", default=[ROOT / "runs" / "demo"], help="run folders")
    parser.add_argument("--figure", type=Path, default=None, help="write the gait-cycle PNG here")
    parser.add_argument("--normative", action="store_true", help="also the joint-angle sweep and its markdown table")
    args = parser.parse_args()
    cfg = MotionConfig()
    _measure(synthetic_trajectories(1.0)["straight_1.0"], 0, cfg)  # warm-up: compiled kernels, caches
    groups: dict[str, list[tuple[dict, float, float]]] = {"synthetic": [], "crowd": []}
    for name, traj in synthetic_trajectories(6.0 if args.quick else 12.0).items():
        quality, cpu, _ = _measure(traj, derive_seed("bench", name), cfg)
        groups["synthetic"].append((quality, cpu, traj.t[-1] - traj.t[0] + 1 / 30))
    files = sorted(p for run in args.runs if run.exists() for p in (run / "scenes").glob("*/crowd.parquet"))
    if args.quick:
        files = files[:1]
    leads: dict[str, list[float]] = {name: [] for name in HEADING_SEGMENTS}
    for path in files:
        for traj in read_trajectories(path):
            quality, cpu, motion = _measure(traj, derive_seed("bench", path.parent.name, traj.ped_id), cfg)
            groups["crowd"].append((quality, cpu, traj.t[-1] - traj.t[0] + 1 / 30))
            found = heading_leads(motion.local_quats, motion.rest_joints, motion.root_pos, traj.xy, traj.t)
            for name, value in found.items():
                if value is not None:
                    leads[name].append(value)
    result: dict = {"targets": {k: f"{op} {v}" for k, (op, v) in TARGETS.items()}}
    for name, rows in groups.items():
        if not rows:
            continue
        qualities = [row[0] for row in rows]
        cpu = sum(row[1] for row in rows)
        minutes = sum(row[2] for row in rows) / 60.0
        summary = _summary(qualities)
        per_minute = cpu / minutes
        checks = {}
        for key, (op, bound) in TARGETS.items():
            value = per_minute if key == "cpu_s_per_ped_minute" else summary[key][op]
            checks[key] = {
                "value": round(float(value), 5),
                "ok": bool(value <= bound if op == "max" else value >= bound),
            }
        result[name] = {
            "pedestrians": len(rows),
            "pedestrian_minutes": round(minutes, 2),
            "cpu_s": round(cpu, 3),
            "cpu_s_per_ped_minute": round(per_minute, 4),
            "checks": checks,
            "all_ok": all(c["ok"] for c in checks.values()),
            "quality": summary,
        }
    result["heading_lead_s"] = {  # > 0: the segment turns before the path (people: head ~0.2 s first)
        name: {
            "median": round(float(np.median(v)), 3),
            "p25": round(float(np.percentile(v, 25)), 3),
            "p75": round(float(np.percentile(v, 75)), 3),
            "pedestrians": len(v),
        }
        for name, v in leads.items()
        if v
    }
    result["crowd_files"] = [str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p) for p in files]
    if args.figure:
        figure(args.figure, cfg)
        result["figure"] = str(args.figure)
    if args.normative:
        result["normative"] = normative(cfg)
    emit(result)
    if args.normative:
        print(normative_table(result["normative"]))  # noqa: T201


if __name__ == "__main__":
    main()
