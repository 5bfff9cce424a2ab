"""Hand-built episodes for runtime tests: an open room, optional walls and pedestrians."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from song.config import RobotConfig
from song.datasets.bench.types import AvatarBinding, Episode, PedestrianTrack, RuntimeParams, StaticMap


def bound_scene(scene_dir: Path) -> tuple[list[PedestrianTrack], list[AvatarBinding]]:
    """The pedestrian tracks and avatar bindings a crowd + binding run wrote into ``scene_dir``."""
    from song.pipeline.motion import read_trajectories

    bindings = json.loads((scene_dir / "binding" / "bindings.json").read_text())["pedestrians"]
    tracks = [PedestrianTrack(t.ped_id, t.t, t.xy, t.yaw) for t in read_trajectories(scene_dir / "crowd.parquet")]
    avatars = [
        AvatarBinding(b["ped_id"], b["avatar_id"], Path(b["asset_path"]), scene_dir / b["cache_file"]) for b in bindings
    ]
    return tracks, avatars


def room_map(width: float = 10.0, height: float = 6.0, res: float = 0.05, walls: list | None = None) -> StaticMap:
    rows, cols = round(height / res), round(width / res)
    cells = np.full((rows, cols), 255, dtype=np.uint8)
    cells[:2, :] = cells[-2:, :] = cells[:, :2] = cells[:, -2:] = 0
    for x0, y0, x1, y1 in walls or []:
        cells[rows - round(y1 / res) : rows - round(y0 / res), round(x0 / res) : round(x1 / res)] = 0
    return StaticMap(cells=cells, resolution=res, origin=(0.0, 0.0))


def track(ped_id: int, start, end, t0: float = 0.0, speed: float = 0.8, fps: int = 30) -> PedestrianTrack:
    start, end = np.asarray(start, float), np.asarray(end, float)
    n = max(2, int(np.linalg.norm(end - start) / speed * fps) + 1)
    t = t0 + np.arange(n) / fps
    w = np.linspace(0.0, 1.0, n)[:, None]
    xy = (1 - w) * start + w * end
    yaw = np.full(n, np.arctan2(*(end - start)[::-1]))
    return PedestrianTrack(ped_id, t, xy, yaw)


def episode(
    start=(1.0, 3.0), goal=(8.0, 3.0), yaw=0.0, peds=(), walls=None, path=None, t0=0.0, robot: RobotConfig | None = None
) -> Episode:
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    path = np.asarray(path if path is not None else [start, goal], float)
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    return Episode(
        episode_id="ep",
        scene_id="room",
        difficulty="easy",
        mode="random",
        seed=0,
        start_xy=start,
        start_yaw=yaw,
        goal_xy=goal,
        goal_radius=1.0,
        geodesic_distance=length,
        optimal_time=length / 0.5,
        t0=t0,
        path=path,
        static_map=room_map(walls=walls),
        pedestrians=list(peds),
        params=RuntimeParams(robot=robot or RobotConfig()),
    )
