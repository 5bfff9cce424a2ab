"""``song viz pov``: an episode through the robot's eyes: RGB | depth | top-down, as H.264 video and a strip.

The policy is run on the episode (as ``song eval`` would, with the release's parameters) with the
``rgb`` and ``depth`` sensors added at the chosen resolution; every control step becomes one frame of
three panels (:mod:`song.runtime.pictures`): the rendered RGB, the depth and the top-down map. So the
video shows at a glance whether people appear where they walk and walls where the map says.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from song.datasets.bench import open_benchmark
from song.render.draw import label, write_png
from song.render.video import write_mp4
from song.runtime.avatars import make_collider
from song.runtime.evaluate import make_setup
from song.runtime.loop import EpisodeRunner, run_episode
from song.runtime.pictures import PANEL_HEIGHT, PovPictures
from song.runtime.policies import load_policy
from song.runtime.sensors import SensorSuite
from song.util import check_id

STRIP_FRAMES = 5


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
