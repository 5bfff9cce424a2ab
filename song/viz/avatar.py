"""A simple splat preview of avatars (OpenCV): Gaussians projected orthographically with their colours.

Not a renderer: each Gaussian becomes a filled disc of its largest in-view standard deviation, drawn
back to front (painter's order), front view (looking along −x) and side view (looking along +y). The
picture shows identities in the rest pose and, when a pose function is given, mid-stride.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from song.datasets.avatars.asset import AvatarAsset
from song.datasets.scenes.ply import SH_C0
from song.util import write_bytes_atomic

PIXELS_PER_M = 160


def _splat(image: np.ndarray, means: np.ndarray, colours: np.ndarray, radii: np.ndarray, view: str, x0: int) -> None:
    """Draw one view of one avatar into ``image`` with its feet on the bottom margin, centred at ``x0``."""
    import cv2

    horizontal, depth = (means[:, 1] * -1, means[:, 0]) if view == "front" else (means[:, 0], -means[:, 1])
    order = np.argsort(depth)  # far first (front view: far = small x; side view: far = large y)
    rows = image.shape[0] - 20 - (means[:, 2] * PIXELS_PER_M)
    cols = x0 + horizontal * PIXELS_PER_M
    rgb = (np.clip(colours, 0, 1) * 255).astype(np.uint8)
    shade = 0.75 + 0.25 * np.clip(depth - depth.min(), 0, None) / max(np.ptp(depth), 1e-6)
    for i in order:
        colour = tuple(int(c * shade[i]) for c in rgb[i])
        cv2.circle(image, (int(cols[i]), int(rows[i])), max(1, int(radii[i] * PIXELS_PER_M)), colour, -1, cv2.LINE_AA)


def draw_avatars(
    assets: Sequence[AvatarAsset],
    out: str | Path,
    pose: Callable[[AvatarAsset], np.ndarray] | None = None,
) -> Path:
    """Write a PNG: per identity a front and a side view in the rest pose (and posed, with ``pose``).

    Args:
        assets: the identities to show (a handful).
        out: PNG path.
        pose: optional ``pose(asset) -> (G, 3)`` posed means (e.g. mid-stride) shown in a second row.
    """
    import cv2

    rows = 2 if pose else 1
    height = int(2.1 * PIXELS_PER_M)
    width_each = int(1.5 * PIXELS_PER_M)
    image = np.full((rows * height, len(assets) * 2 * width_each, 3), 245, np.uint8)
    for k, asset in enumerate(assets):
        cloud = asset.gaussians
        colours = 0.5 + SH_C0 * cloud.sh_dc
        radii = np.exp(cloud.log_scales).max(axis=1) * 1.2
        stages = [cloud.means] + ([pose(asset)] if pose else [])
        for row, means in enumerate(stages):
            band = image[row * height : (row + 1) * height]
            centre = means[:, :2].mean(axis=0)
            shifted = means - np.array([centre[0], centre[1], 0.0])
            for v, view in enumerate(("front", "side")):
                _splat(band, shifted, colours, radii, view, (2 * k + v) * width_each + width_each // 2)
        cv2.putText(
            image, asset.avatar_id, (2 * k * width_each + 8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (60, 60, 60), 1
        )
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError(f"{out}: PNG encoding failed")
    write_bytes_atomic(out, data.tobytes())
    return Path(out)


@functools.cache
def walk_motion():
    """Three seconds of the procedural gait walking straight at 1.2 m/s (a :class:`Motion`, computed once)."""
    from song.config import MotionConfig
    from song.pipeline.motion import synthesize_motions
    from song.pipeline.motion.synthetic import trajectory_from_profiles

    frames = 90
    walk = trajectory_from_profiles(0, np.full(frames, 1.2), np.zeros(frames))
    [(motion, _)] = synthesize_motions([walk], [""], [0], MotionConfig(generator="procedural"))
    return motion


def mid_stride(asset: AvatarAsset) -> np.ndarray:
    """The asset's Gaussian means mid-stride: procedural gait walking at 1.2 m/s, posed by LBS."""
    from song.datasets.avatars.cache import skin_asset
    from song.geometry.fk import skinning_transforms
    from song.geometry.lbs import lbs_positions

    motion = walk_motion()
    scale = asset.height_m / float(motion.height_m)
    rest = asset.rest_joints.astype(np.float64)
    f = int(np.argmax(np.abs(motion.joints[:, 7, 0] - motion.joints[:, 8, 0])[30:])) + 30  # feet furthest apart
    transforms = skinning_transforms(rest, motion.local_quats[f], motion.root_pos[f] * scale)
    return lbs_positions(skin_asset(asset), transforms.astype(np.float32))


def render_gallery(
    assets: Sequence[AvatarAsset],
    out: str | Path,
    distances: Sequence[float] = (2.0, 5.0),
    camera_height_m: float = 0.8,
    size: tuple[int, int] = (640, 400),
    hfov_deg: float = 70.0,
) -> Path:
    """Write a PNG of identities as a robot sees them: the real renderer, a robot camera at each distance.

    The identities stand side by side (0.75 m apart, mid-stride when the pose is available, facing the
    camera) on a light floor-less background; one panel per distance, left to right.
    """
    import cv2

    from song.render import GaussianSet, look_at, render

    sets = []
    spacing = 0.75
    for k, asset in enumerate(assets):
        cloud = asset.gaussians
        means = mid_stride(asset).astype(np.float64)
        means -= np.array([means[:, 0].mean(), means[:, 1].mean(), 0.0])
        means = means @ np.diag([-1.0, -1.0, 1.0])  # turn to face −x, towards the camera
        means[:, 1] += (k - (len(assets) - 1) / 2) * spacing
        q = cloud.quats  # the same turn for the discs: (0, 0, 0, 1) ⊗ (w, x, y, z) = (−z, −y, x, w)
        quats = np.column_stack([-q[:, 3], -q[:, 2], q[:, 1], q[:, 0]])
        sets.append(GaussianSet.from_raw(means, quats, cloud.log_scales, cloud.opacity_logits, cloud.sh_dc))
    panels = []
    for d in distances:
        eye = np.array([-d, 0.0, camera_height_m])
        camera = look_at(eye, np.array([0.0, 0.0, 0.9]), size[0], size[1], hfov_deg)
        rgb = render(sets, camera, backend="numba", background=(0.93, 0.93, 0.91)).rgb
        panel = np.ascontiguousarray(rgb)
        cv2.putText(
            panel, f"robot camera at {d:g} m", (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (40, 40, 40), 1, cv2.LINE_AA
        )
        panels.append(panel)
    image = np.concatenate(panels, axis=1)
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError(f"{out}: PNG encoding failed")
    write_bytes_atomic(out, data.tobytes())
    return Path(out)
