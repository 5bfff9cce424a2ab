"""``song viz crowd``: every pedestrian's trajectory over the map (PNG) and an animation (MP4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from song.datasets.run import RunFolder, read_crowd, read_intents, read_run_info
from song.datasets.scenes import load_scene_package
from song.render.draw import colour, label, write_png
from song.render.video import write_mp4
from song.util import check_id
from song.viz.scene import draw_scene


def _tracks(crowd_file: Path) -> tuple[dict[int, np.ndarray], int]:
    """Per pedestrian (frame, x, y) rows, and the frame rate."""
    crowd = read_crowd(crowd_file)
    frames = np.arange(crowd.xy.shape[1], dtype=np.float64)
    return {int(p): np.column_stack([frames, crowd.xy[k]]) for k, p in enumerate(crowd.ids)}, crowd.fps


def render_crowd(run_dir: str | Path, scene_id: str, out_dir: str | Path, video: bool = True) -> list[Path]:
    """Write ``<scene>_crowd.png`` (and ``<scene>_crowd.mp4``) into ``out_dir``."""
    import cv2

    run, out_dir = RunFolder(Path(run_dir)), Path(out_dir)
    scene = run.scene(scene_id)
    canvas = draw_scene(load_scene_package(read_run_info(run.root).scenes_dir / scene_id), labels=False)
    tracks, fps = _tracks(scene.crowd)
    intents = read_intents(scene.intents).by_id() if scene.intents.is_file() else {}
    still = canvas.image.copy()
    for ped_id, data in tracks.items():
        pts = canvas.px(data[:, 1:])
        cv2.polylines(still, [pts], False, colour(ped_id), 2, cv2.LINE_AA)
        cv2.circle(still, tuple(int(v) for v in pts[0]), 5, colour(ped_id), -1, cv2.LINE_AA)
        cv2.drawMarker(still, tuple(int(v) for v in pts[-1]), colour(ped_id), cv2.MARKER_TILTED_CROSS, 12, 2)
        intent = intents.get(ped_id)
        text = f"{ped_id}: {intent.start_object} -> {intent.goal_object}" if intent else f"{ped_id}"
        label(still, text, (int(pts[0][0]) + 6, int(pts[0][1]) - 6), colour(ped_id), 0.38)
    written = [write_png(out_dir / f"{check_id(scene_id, 'scene id')}_crowd.png", still)]
    if video and tracks:
        last = int(max(d[-1, 0] for d in tracks.values()))
        frames = []
        scale = canvas.scale
        step = max(1, round(fps / 10))
        for frame in range(0, last + 1, step):  # a 10 FPS animation of the plan
            image = canvas.image.copy()
            for ped_id, data in tracks.items():
                seen = data[data[:, 0] <= frame]
                if len(seen) == 0:
                    continue
                pts = canvas.px(seen[-90:, 1:])
                cv2.polylines(image, [pts], False, colour(ped_id), 1, cv2.LINE_AA)
                cv2.circle(image, tuple(int(v) for v in pts[-1]), max(3, int(0.25 * scale)), colour(ped_id), -1)
            label(image, f"t = {frame / fps:5.1f} s", (10, 20), (0, 0, 0), 0.5)
            frames.append(image)
        written.append(write_mp4(out_dir / f"{scene_id}_crowd.mp4", frames, fps=10))
    return written
