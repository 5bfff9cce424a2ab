"""Pictures of a running episode: RGB | depth | top-down map, one per control step.

What ``song viz pov`` writes as a video and what the Gymnasium env's ``render()`` returns: the rendered
RGB, the depth (turbo colour map, 0–8 m, black where nothing is seen) and the map with the robot's
path so far, its field of view, the goal and the pedestrians where the crowd has them at that instant.
"""

from __future__ import annotations

import math

import numpy as np

from song.datasets.bench import pedestrian_states
from song.render.draw import Canvas, colour, map_canvas
from song.runtime.loop import EpisodeRunner
from song.runtime.sensors import SensorSuite

PANEL_HEIGHT = 360  # px of every panel
DEPTH_RANGE_M = 8.0


def depth_image(depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 turbo colours of a depth image (near red → far blue), black where depth is 0."""
    import cv2

    scaled = np.clip(1.0 - depth / DEPTH_RANGE_M, 0.0, 1.0)
    rgb = cv2.cvtColor(cv2.applyColorMap((scaled * 255).astype(np.uint8), cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[depth <= 0] = 0
    return rgb


def depth_legend(panel: np.ndarray) -> np.ndarray:
    """The depth panel with a colour bar at its right edge: 0 m at the bottom, DEPTH_RANGE_M at the top."""
    from song.render.draw import label

    height, width = panel.shape[:2]
    top, bottom, x0 = height // 6, height - height // 6, width - 22
    ramp = np.linspace(DEPTH_RANGE_M, 0.0, bottom - top)[:, None].repeat(10, axis=1)
    out = panel.copy()
    out[top - 1 : bottom + 1, x0 - 1 : x0 + 11] = 255
    out[top:bottom, x0 : x0 + 10] = depth_image(ramp)
    label(out, f"{DEPTH_RANGE_M:g} m", (x0 - 34, top + 8), (0, 0, 0), 0.4)
    label(out, "0 m", (x0 - 26, bottom), (0, 0, 0), 0.4)
    return out


def _fit(image: np.ndarray, height: int) -> np.ndarray:
    import cv2

    width = round(image.shape[1] * height / image.shape[0])
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_NEAREST)


def _map_panel(canvas: Canvas, runner: EpisodeRunner, fov_deg: float) -> np.ndarray:
    import cv2

    image = canvas.image.copy()
    episode = runner.episode
    goal = canvas.px(episode.goal_xy)
    cv2.circle(image, tuple(int(v) for v in goal), int(episode.goal_radius * canvas.scale), (40, 160, 40), 2)
    path = np.array([[p.x, p.y] for p in runner.poses])
    cv2.polylines(image, [canvas.px(path)], False, (20, 20, 20), 2, cv2.LINE_AA)
    _, peds, _ = pedestrian_states(episode.pedestrians, runner.time)
    for track, p in zip(episode.pedestrians, peds, strict=True):
        cv2.circle(
            image, tuple(int(v) for v in canvas.px(p)), max(3, int(0.25 * canvas.scale)), colour(track.ped_id), -1
        )
    pose = runner.pose
    reach = 3.0
    half = math.radians(fov_deg) / 2
    wedge = [pose.xy] + [
        pose.xy + reach * np.array([math.cos(a), math.sin(a)]) for a in pose.yaw + np.linspace(-half, half, 9)
    ]
    overlay = image.copy()
    cv2.fillPoly(overlay, [canvas.px(np.array(wedge))], (255, 200, 60))
    image = cv2.addWeighted(overlay, 0.35, image, 0.65, 0)
    cv2.circle(image, tuple(int(v) for v in canvas.px(pose.xy)), max(3, int(0.2 * canvas.scale)), (20, 20, 20), -1)
    return image


def _pad_to(image: np.ndarray, width: int) -> np.ndarray:
    if image.shape[1] >= width:
        return image[:, :width]
    pad = np.full((image.shape[0], width - image.shape[1], 3), 255, np.uint8)
    return np.concatenate([image, pad], axis=1)


class PovPictures:
    """Frames of RGB | depth | top-down map for a running episode (``song viz pov``, the env's ``render``).

    Args:
        params: the runtime parameters (camera and robot).
        max_pedestrians: the release's largest scene (sensor capacity).
        camera: the camera sensors' options (``width``, ``height``, ``backend``, ``model``).
    """

    def __init__(self, params, max_pedestrians: int, camera: dict) -> None:
        self.sensors = SensorSuite.build(("rgb", "depth"), params, max_pedestrians, {"camera": dict(camera)})
        self.fov = params.camera.hfov_deg
        self._episode = None

    def _start(self, episode) -> None:
        self._episode = episode
        self.sensors.reset(episode)
        sm = episode.static_map
        self.canvas = map_canvas(sm.cells, sm.resolution, sm.origin, max_pixels=PANEL_HEIGHT * 2)
        self.map_width = round(self.canvas.image.shape[1] * PANEL_HEIGHT / self.canvas.image.shape[0])

    def frame(self, runner: EpisodeRunner, observation: dict | None = None) -> np.ndarray:
        """(PANEL_HEIGHT, W, 3) uint8 picture of the runner's current step.

        ``observation`` holding ``rgb`` and ``depth`` (the runner's own) is used instead of rendering again.
        """
        if runner.episode is not self._episode:
            self._start(runner.episode)
        if observation is not None and "rgb" in observation and "depth" in observation:
            obs = observation
        else:
            obs = self.sensors.observe(runner.view())
        panels = [_fit(obs["rgb"], PANEL_HEIGHT), depth_legend(_fit(depth_image(obs["depth"]), PANEL_HEIGHT))]
        map_panel = _fit(_map_panel(self.canvas, runner, self.fov), PANEL_HEIGHT)
        panels.append(_pad_to(map_panel, min(self.map_width, 2 * PANEL_HEIGHT)))
        return np.concatenate(panels, axis=1)
