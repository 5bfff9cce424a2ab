"""Camera models: what a real sensor does to the renderer's ideal image and depth.

``ideal`` (:class:`song.runtime.vision.IdealCamera`) leaves the render as it is: the paper's protocol and
the default. ``d435i`` approximates an Intel RealSense D435i, the paper's robot camera. Its depth:

- **Stereo error growing with the square of the distance.** A stereo camera measures disparity
  d = f·B / z; a disparity error σ_d gives σ_z = z² σ_d / (f B). Intel's D400-series datasheet
  (Intel RealSense D400 Series Product Family Datasheet, rev. 013, Table "Depth Module Depth Quality
  Specification") states depth RMS error ≤ 2 % at 2 m (within 50 % of the field of view, ≤ 848×480).
  With the D435i's baseline B = 50 mm and its depth imager's focal length at 848×480 (87° horizontal
  FOV: f = 424 / tan 43.5° = 447 px), 2 % at 2 m is σ_d = 0.04 m · 447 px · 0.05 m / (2 m)² = 0.223 px.
  So σ_z(z) = 0.01 m⁻¹ · z², i.e. 0.5 % at 1 m, 2 % at 2 m, 4 % at 4 m: the datasheet's bound taken
  as the typical error, so the noise is an honest worst case of a calibrated unit. The noise is drawn
  independently per pixel (a real stereo matcher's error is spatially correlated over its window; not
  modelled);
- **range**: no depth nearer than 0.28 m (the datasheet's minimum depth at 848×480) or beyond 10 m;
- **holes at depth discontinuities**: a background pixel that the left imager sees but the right one
  does not (the foreground hides it) has no match. At disparity d_p, a pixel is occluded when a pixel
  s columns to its right is nearer by a disparity of at least s: d_{p+s} − d_p ≥ s, with disparities
  in this image's pixels (d = f·B/z for this image's focal length f). Such pixels read 0;
- **flying pixels**: the renderer's alpha-blended silhouette depths already lie between the two
  surfaces, as a real matcher's do; they are kept;
- **quantisation** to the sensor's 1 mm depth unit.

Its colour: auto-exposure from the frame's mean luminance (linear light, target 0.45, gain within
[0.5, 4]); photon shot noise (full well 5,000 electrons at the clipping level; drawn by its normal
limit, exact to well under a grey level at these counts) and read noise (3 electrons) in linear light; motion blur along the image rows over the exposure (10 ms) from the
robot's turning rate during the step (the dominant image motion of a ground robot); sRGB encoding
and 8-bit quantisation. Lens distortion is not modelled (the renderer is a pinhole camera).

Every draw comes from a generator seeded by (episode seed, control step), so the same episode and
step give the same image in any process. The model never writes depth where the ideal render had
none: it only adds noise to valid pixels or removes them.
"""

from __future__ import annotations

import math

import numpy as np

from song import plugins
from song.datasets.scenes.materials import linear_to_srgb, srgb_to_linear
from song.render import RenderOutput
from song.render.camera import focal_from_hfov
from song.runtime.vision import CameraContext

BASELINE_M = 0.050  # D435i stereo baseline
DATASHEET_RMS_AT_2M = 0.02  # ≤ 2 % at 2 m (Intel D400 datasheet)
D435I_FOCAL_PX = 424.0 / math.tan(math.radians(87.0 / 2))  # depth imager, 848×480, 87° HFOV
SIGMA_DISPARITY_PX = DATASHEET_RMS_AT_2M * 2.0 * D435I_FOCAL_PX * BASELINE_M / 2.0**2
MIN_DEPTH_M, MAX_DEPTH_M = 0.28, 10.0
DEPTH_UNIT_M = 0.001
EXPOSURE_S = 0.010
FULL_WELL_E, READ_NOISE_E = 5000.0, 3.0
TARGET_LUMINANCE, GAIN_RANGE = 0.45, (0.5, 4.0)
MAX_SHADOW_PX = 32  # occlusion shadows wider than this are not searched (a few cm from the camera)


def depth_sigma_m(z: np.ndarray | float) -> np.ndarray | float:
    """The model's depth RMS error at distance ``z``, m: z² σ_d / (f B) with the D435i's f and B."""
    return np.asarray(z) ** 2 * SIGMA_DISPARITY_PX / (D435I_FOCAL_PX * BASELINE_M)


def occluded(depth: np.ndarray, focal_px: float, baseline_m: float = BASELINE_M) -> np.ndarray:
    """(H, W) bool: pixels with depth whose right-imager view is blocked by a nearer pixel to their right."""
    depth = np.asarray(depth, np.float32)
    disparity = np.where(depth > 0, np.float32(focal_px * baseline_m) / np.maximum(depth, np.float32(1e-6)), 0)
    out = np.zeros(depth.shape, dtype=bool)
    for s in range(1, min(MAX_SHADOW_PX, depth.shape[1] - 1) + 1):
        out[:, :-s] |= disparity[:, s:] - disparity[:, :-s] >= s
    return out & (depth > 0)


LINEAR_OF_U8 = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)  # 8-bit sRGB → linear light
LUT_STEPS = 4096
U8_OF_LINEAR = np.rint(linear_to_srgb(np.arange(LUT_STEPS) / (LUT_STEPS - 1)) * 255.0).astype(np.uint8)


def _blur_rows(image: np.ndarray, length_px: float) -> np.ndarray:
    """A horizontal box blur of ``length_px`` (fractional lengths weight the last tap)."""
    if length_px < 1.0:
        return image
    n = int(math.floor(length_px))
    weights = np.ones(n + 1)
    weights[-1] = length_px - n
    weights /= weights.sum()
    padded = np.pad(image, ((0, 0), (n, 0), (0, 0)), mode="edge")
    out = np.zeros_like(image)
    for k, w in enumerate(weights.astype(image.dtype)):
        if w > 0:
            out += w * padded[:, n - k : n - k + image.shape[1]]
    return out


class D435iCamera:
    """The ``d435i`` camera model (see the module docstring)."""

    name = "d435i"

    def __init__(self, params: object) -> None:
        self.params = params

    def apply(self, frame: RenderOutput, context: CameraContext) -> RenderOutput:
        """The frame as the D435i would deliver it at this step."""
        step = int(round(context.t * 1000.0))
        rng = np.random.default_rng([int(context.seed) & 0xFFFFFFFF, step & 0xFFFFFFFF, 435])
        height, width = frame.depth.shape
        focal = focal_from_hfov(width, float(self.params.camera.hfov_deg))
        depth = self._depth(frame.depth, rng, focal)
        rgb, display = self._colour(frame, context, rng, focal)
        return RenderOutput(rgb, depth, frame.alpha, display)

    def _depth(self, ideal: np.ndarray, rng: np.random.Generator, focal: float) -> np.ndarray:
        depth = np.asarray(ideal, np.float32)
        valid = (depth >= MIN_DEPTH_M) & (depth <= MAX_DEPTH_M)
        noisy = depth + rng.standard_normal(depth.shape, np.float32) * depth_sigma_m(depth).astype(np.float32)
        noisy = np.rint(noisy / np.float32(DEPTH_UNIT_M)) * np.float32(DEPTH_UNIT_M)
        valid &= ~occluded(depth, focal) & (noisy > 0)
        return np.where(valid, noisy, 0.0).astype(np.float32)

    def _colour(
        self, frame: RenderOutput, context: CameraContext, rng: np.random.Generator, focal: float
    ) -> tuple[np.ndarray, np.ndarray]:
        linear = LINEAR_OF_U8[frame.rgb]
        luminance = float((linear @ np.array([0.2126, 0.7152, 0.0722], np.float32)).mean())
        gain = np.float32(np.clip(TARGET_LUMINANCE / max(luminance, 1e-6), *GAIN_RANGE))
        linear = _blur_rows(linear * gain, abs(context.command[1]) * EXPOSURE_S * focal)
        electrons = np.clip(linear, 0.0, 1.0) * np.float32(FULL_WELL_E)
        # shot noise (Poisson, by its normal limit: a pixel holds hundreds of electrons) plus read noise
        electrons += np.sqrt(electrons + np.float32(READ_NOISE_E**2)) * rng.standard_normal(electrons.shape, np.float32)
        steps = np.clip(electrons * np.float32((LUT_STEPS - 1) / FULL_WELL_E), 0, LUT_STEPS - 1).astype(np.int32)
        rgb = U8_OF_LINEAR[steps]
        return rgb, rgb.astype(np.float32) / np.float32(255.0)


plugins.add("camera_model", "d435i", D435iCamera)
