"""Postures at objects on the sample crowds: hands resting on counters, desks and tables; browsing shelves.

.venv/bin/python benchmarks/postures.py [--seed 0]

Runs intents + crowd on the shipped sample scenes into a scratch folder, then generates the procedural
gait of every pedestrian with its stays (``song.pipeline.motion.stage.with_stays``) and reports, as one
JSON object:
- surfaces: stays (runs of frames with ``Trajectory.surface``) and how many have both hands on the
  surface at their middle frame (mid-palm within 1 cm of ``PALM_M`` above the top), by top height;
  pedestrians resting their hands at least once; frames at full lean with the hands off the surface;
- shelves: browsing pedestrians, stays and seconds, and touches (``browse_plan(...).reach`` reaching 1).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, emit  # noqa: E402

from song.config import MotionConfig, SongConfig  # noqa: E402
from song.datasets.run import SceneFolder, read_intents  # noqa: E402
from song.datasets.scenes import load_scene_package  # noqa: E402
from song.geometry.skeleton import JOINT_INDEX as J  # noqa: E402
from song.pipeline.chain import iter_run  # noqa: E402
from song.pipeline.motion.gait import _Body, _plan_signals, generate_gait, style_for  # noqa: E402
from song.pipeline.motion.postures import PALM_M, browse_plan  # noqa: E402
from song.pipeline.motion.stage import read_trajectories, with_stays  # noqa: E402
from song.pipeline.motion.types import true_runs  # noqa: E402

SCENES = ROOT / "datasets" / "sample_scenes"
TOPS_M = {"0.70-0.80": (0.7, 0.8), "0.80-0.95": (0.8, 0.95), "0.95-1.20": (0.95, 1.2001)}
HANDS = [J["left_hand"], J["right_hand"]]


def _surface_figures(traj, joints: np.ndarray, style, tally: dict) -> None:
    rested = False
    for lo, hi in true_runs(np.isfinite(traj.surface[:, 0])):
        middle = (lo + hi) // 2
        top = traj.surface[middle, 1]
        on = bool(np.abs(joints[middle, HANDS, 2] - top - PALM_M).max() < 0.01)
        rested |= on
        band = next(name for name, (lo, hi) in TOPS_M.items() if lo <= top < hi)
        tally["stays"][band] += 1
        tally["rested"][band] += int(on)
    tally["pedestrians"] += 1
    tally["pedestrians_resting"] += int(rested)
    hold, _ = _Body(style.height_m).hands_on_surface(
        traj, 1.0 - _plan_signals(traj).walk, 0.5 * np.radians(style.lean_deg)
    )
    full = np.flatnonzero(hold > 0.99)
    off = np.abs(joints[full][:, HANDS, 2] - traj.surface[full, 1][:, None] - PALM_M).max(axis=1) >= 0.01
    tally["full_lean_frames"] += len(full)
    tally["full_lean_frames_hands_off"] += int(off.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    surfaces = {
        "pedestrians": 0,
        "pedestrians_resting": 0,
        "stays": dict.fromkeys(TOPS_M, 0),
        "rested": dict.fromkeys(TOPS_M, 0),
        "full_lean_frames": 0,
        "full_lean_frames_hands_off": 0,
    }
    shelves = {"pedestrians": 0, "stays": 0, "seconds": 0.0, "touches": 0}
    pedestrians = 0
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        config = SongConfig(seed=args.seed)
        results = list(iter_run(SCENES, run, config, ["intents", "crowd"], executor="serial"))
        for result in results:
            folder = SceneFolder(run / "scenes" / result.scene_id)
            objects = load_scene_package(SCENES / result.scene_id).semantic_map.object_by_id()
            trajectories = read_trajectories(folder.crowd)
            pedestrians += len(trajectories)
            for traj in with_stays(trajectories, read_intents(folder.intents).by_id(), objects):
                if traj.surface is None and traj.shelf is None:
                    continue
                style = style_for(traj.ped_id, MotionConfig())
                joints = generate_gait(traj, style).joints
                if traj.surface is not None:
                    _surface_figures(traj, joints, style, surfaces)
                if traj.shelf is not None:
                    held = np.isfinite(traj.shelf[:, 0])
                    reach = browse_plan(traj.shelf, traj.fps, traj.ped_id).reach >= 0.999
                    shelves["pedestrians"] += 1
                    shelves["stays"] += len(true_runs(held))
                    shelves["seconds"] += held.sum() / traj.fps
                    shelves["touches"] += int(np.sum(np.diff(reach.astype(np.int8)) == 1))
    shelves["seconds"] = round(shelves["seconds"], 1)
    emit({"scenes": len(results), "seed": args.seed, "pedestrians": pedestrians, "surfaces": surfaces,
          "shelves": shelves})  # fmt: skip


if __name__ == "__main__":
    main()
