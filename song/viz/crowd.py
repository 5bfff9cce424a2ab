"""``song viz crowd``: every pedestrian's trajectory over the map (PNG) and an animation (MP4)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from song.datasets.scenes import load_scene_package
from song.viz.draw import colour, label, write_mp4, write_png
from song.viz.scene import draw_scene


def _tracks(scene_dir: Path) -> dict[int, np.ndarray]:
    table = pq.read_table(scene_dir / "crowd.parquet", columns=["ped_id", "frame", "x", "y"]).to_pydict()
    ped = np.asarray(table["ped_id"])
    data = np.column_stack([table["frame"], table["x"], table["y"]])
    return {int(p): data[ped == p] for p in np.unique(ped)}


def render_crowd(run_dir: str | Path, scene_id: str, out_dir: str | Path, video: bool = True) -> list[Path]:
    """Write ``<scene>_crowd.png`` (and ``<scene>_crowd.mp4``) into ``out_dir``."""
    import cv2

    run_dir, out_dir = Path(run_dir), Path(out_dir)
    scene_dir = run_dir / "scenes" / scene_id
    scenes_root = Path(json.loads((run_dir / "run.json").read_text())["scenes_dir"])
    canvas = draw_scene(load_scene_package(scenes_root / scene_id), labels=False)
    tracks = _tracks(scene_dir)
    intents = {}
    if (scene_dir / "intents.json").is_file():
        intents = {i["id"]: i for i in json.loads((scene_dir / "intents.json").read_text())["intents"]}
    still = canvas.image.copy()
    for ped_id, data in tracks.items():
        pts = canvas.px(data[:, 1:])
        cv2.polylines(still, [pts], False, colour(ped_id), 2, cv2.LINE_AA)
        cv2.circle(still, tuple(int(v) for v in pts[0]), 5, colour(ped_id), -1, cv2.LINE_AA)
        cv2.drawMarker(still, tuple(int(v) for v in pts[-1]), colour(ped_id), cv2.MARKER_TILTED_CROSS, 12, 2)
        intent = intents.get(ped_id, {})
        text = f"{ped_id}: {intent.get('start_object', '?')} -> {intent.get('goal_object', '?')}"
        label(still, text, (int(pts[0][0]) + 6, int(pts[0][1]) - 6), colour(ped_id), 0.38)
    written = [write_png(out_dir / f"{scene_id}_crowd.png", still)]
    if video and tracks:
        last = int(max(d[-1, 0] for d in tracks.values()))
        frames = []
        scale = canvas.scale
        for frame in range(0, last + 1, 3):  # 10 FPS animation of the 30 FPS plan
            image = canvas.image.copy()
            for ped_id, data in tracks.items():
                seen = data[data[:, 0] <= frame]
                if len(seen) == 0:
                    continue
                pts = canvas.px(seen[-90:, 1:])
                cv2.polylines(image, [pts], False, colour(ped_id), 1, cv2.LINE_AA)
                cv2.circle(image, tuple(int(v) for v in pts[-1]), max(3, int(0.25 * scale)), colour(ped_id), -1)
            label(image, f"t = {frame / 30:5.1f} s", (10, 20), (0, 0, 0), 0.5)
            frames.append(image)
        written.append(write_mp4(out_dir / f"{scene_id}_crowd.mp4", frames, fps=10))
    return written
