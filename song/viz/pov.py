"""``song viz pov``: an episode through the robot's eyes: RGB | depth | top-down, as H.264 video and a strip.

The policy is run on the episode (as ``song eval`` would, with the release's parameters) with the
``rgb`` and ``depth`` sensors added at the chosen resolution; every control step becomes one frame of
three panels: the rendered RGB, the depth (turbo colour map, 0–8 m, black where nothing is seen) and
the map with the robot's path so far, its field of view, the goal and the pedestrians where the crowd
has them at that instant. So the video shows at a glance whether people appear where they walk and
walls where the map says.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np

from song.datasets.bench import open_benchmark, pedestrian_states
from song.render.video import write_mp4
from song.runtime.avatars import make_collider
from song.runtime.evaluate import make_setup
from song.runtime.loop import EpisodeRunner, run_episode
from song.runtime.policies import load_policy
from song.runtime.sensors import SensorSuite
from song.util import check_id
from song.viz.draw import Canvas, colour, label, map_canvas, write_png

PANEL_HEIGHT = 360  # px of every panel in the video
DEPTH_RANGE_M = 8.0
STRIP_FRAMES = 5


def depth_image(depth: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) uint8 turbo colours of a depth image (near red → far blue), black where depth is 0."""
    import cv2

    scaled = np.clip(1.0 - depth / DEPTH_RANGE_M, 0.0, 1.0)
    rgb = cv2.cvtColor(cv2.applyColorMap((scaled * 255).astype(np.uint8), cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[depth <= 0] = 0
    return rgb


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
        panels = [_fit(obs["rgb"], PANEL_HEIGHT), _fit(depth_image(obs["depth"]), PANEL_HEIGHT)]
        map_panel = _fit(_map_panel(self.canvas, runner, self.fov), PANEL_HEIGHT)
        panels.append(_pad_to(map_panel, min(self.map_width, 2 * PANEL_HEIGHT)))
        return np.concatenate(panels, axis=1)


def render_pov(
    bench: str,
    episode_id: str,
    policy: str,
    out_dir: str | Path,
    size: tuple[int, int] = (320, 240),
    backend: str = "auto",
) -> list[Path]:
    """Run ``policy`` on the episode; write its first-person video and pictures.

    ``<episode>_<policy>_pov.mp4``, ``..._pov.png`` (a strip of five frames) and ``..._pov_first.png``
    (the first frame's RGB | depth).
    """
    release = open_benchmark(bench)
    width, height = size
    camera = {"width": width, "height": height, "backend": backend}
    setup = make_setup(release, policy, ["rgb", "depth"], camera=camera)
    episode = dataclasses.replace(release.episode(episode_id), params=setup.params)
    sensors = SensorSuite.build(setup.sensors, setup.params, release.max_pedestrians, setup.sensor_options)
    pictures = PovPictures(setup.params, release.max_pedestrians, setup.sensor_options["camera"])
    frames: list[np.ndarray] = []

    def grab(runner: EpisodeRunner) -> None:
        frame = pictures.frame(runner, runner.observation())
        label(frame, f"{episode_id} {policy} t = {runner.time - episode.t0:5.1f} s", (10, 22), (0, 0, 0), 0.6)
        frames.append(frame)

    result = run_episode(episode, load_policy(policy), make_collider(episode), sensors, on_step=grab)
    label(frames[-1], f"outcome: {result.outcome}", (10, 48), (0, 0, 0), 0.6)
    out_dir = Path(out_dir)
    stem = f"{check_id(episode_id, 'episode id')}_{re.sub(r'[^A-Za-z0-9_-]', '_', policy)}_pov"
    fps = setup.params.robot.control_hz
    video = write_mp4(out_dir / f"{stem}.mp4", frames, fps=fps)
    picks = np.linspace(0, len(frames) - 1, min(STRIP_FRAMES, len(frames))).round().astype(int)
    strip = np.concatenate([frames[k][::2, ::2] for k in picks], axis=0)
    camera_panels = 2 * round(width * PANEL_HEIGHT / height)  # the first frame's RGB | depth, full size
    first = write_png(out_dir / f"{stem}_first.png", frames[0][:, :camera_panels])
    return [video, write_png(out_dir / f"{stem}.png", strip), first]
