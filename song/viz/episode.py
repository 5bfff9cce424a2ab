"""``song viz episode``: map, pedestrians over time, the A* path, the robot's path and its events."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq

from song.datasets.bench import open_benchmark, pedestrian_states
from song.render.draw import colour, label, map_canvas, write_png
from song.render.video import write_mp4
from song.util import check_id

ENCOUNTER_RADIUS_M = 3.0


def _robot_log(results: Path | None, episode_id: str) -> dict | None:
    if results is None:
        return None
    table = pq.read_table(results)
    rows = table.filter(pc.equal(table.column("episode_id"), episode_id)).to_pylist()
    return rows[0] if rows else None


def render_episode(
    bench: str, episode_id: str, out_dir: str | Path, results: str | Path | None = None, video: bool = True
):
    """Write ``<episode>.png`` (and ``.mp4``) into ``out_dir``; returns the paths."""
    import cv2

    episode = open_benchmark(bench).episode(episode_id)
    log = _robot_log(Path(results) if results else None, episode_id)
    sm = episode.static_map
    canvas = map_canvas(sm.cells, sm.resolution, sm.origin)
    base = canvas.image
    for track in episode.pedestrians:
        cv2.polylines(base, [canvas.px(track.xy)], False, tuple(int(0.5 * c + 120) for c in colour(track.ped_id)), 1)
    path = canvas.px(episode.path)
    for a, b in zip(path[:-1], path[1:], strict=True):  # dashed A* path
        n = max(2, int(np.linalg.norm(b - a) / 8))
        for k in range(0, n - 1, 2):
            p = a + (b - a) * k / n
            q = a + (b - a) * (k + 1) / n
            cv2.line(base, tuple(int(v) for v in p), tuple(int(v) for v in q), (40, 40, 200), 2, cv2.LINE_AA)
    start, goal = canvas.px(episode.start_xy), canvas.px(episode.goal_xy)
    cv2.circle(
        base, tuple(int(v) for v in goal), int(episode.goal_radius * canvas.scale), (40, 160, 40), 2, cv2.LINE_AA
    )
    cv2.drawMarker(base, tuple(int(v) for v in start), (40, 40, 200), cv2.MARKER_TRIANGLE_UP, 16, 2)
    robot = np.asarray(log["trajectory"])[:, :2] if log else None
    times = episode.t0 + np.arange(len(robot)) * 0.1 if robot is not None else None
    still = base.copy()
    if robot is not None:
        cv2.polylines(still, [canvas.px(robot)], False, (20, 20, 20), 2, cv2.LINE_AA)
        for event in log["events"]:
            p = canvas.px(robot[min(event["step"], len(robot) - 1)])
            rgb = (220, 30, 30) if event["kind"] in ("human", "obstacle") else (230, 150, 0)
            cv2.drawMarker(still, tuple(int(v) for v in p), rgb, cv2.MARKER_TILTED_CROSS, 14, 2)
        for t, xy in zip(times, robot, strict=True):  # encounters: people within 3 m along the run
            _, ped, _ = pedestrian_states(episode.pedestrians, float(t))
            for p in ped[np.linalg.norm(ped - xy, axis=1) < ENCOUNTER_RADIUS_M]:
                cv2.circle(still, tuple(int(v) for v in canvas.px(p)), 2, (255, 140, 0), -1)
        label(still, f"{episode_id} [{episode.difficulty}] outcome: {log['outcome']}", (10, 20), (0, 0, 0), 0.5)
    else:
        label(
            still, f"{episode_id} [{episode.difficulty}] L*={episode.geodesic_distance:.1f} m", (10, 20), (0, 0, 0), 0.5
        )
    out_dir = Path(out_dir)
    written = [write_png(out_dir / f"{check_id(episode_id, 'episode id')}.png", still)]
    if video:
        n = len(robot) if robot is not None else int(episode.optimal_time / 0.1) + 1
        frames = []
        for k in range(n):
            t = episode.t0 + k * 0.1
            image = base.copy()
            _, ped, _ = pedestrian_states(episode.pedestrians, t)
            for track, p in zip(episode.pedestrians, ped, strict=True):
                cv2.circle(
                    image,
                    tuple(int(v) for v in canvas.px(p)),
                    max(3, int(0.25 * canvas.scale)),
                    colour(track.ped_id),
                    -1,
                )
            if robot is not None:
                cv2.polylines(image, [canvas.px(robot[: k + 1])], False, (20, 20, 20), 2, cv2.LINE_AA)
                cv2.circle(
                    image, tuple(int(v) for v in canvas.px(robot[k])), max(3, int(0.2 * canvas.scale)), (20, 20, 20), -1
                )
            label(image, f"t = {t:5.1f} s", (10, 20), (0, 0, 0), 0.5)
            frames.append(image)
        written.append(write_mp4(out_dir / f"{episode_id}.mp4", frames, fps=10))
    return written
