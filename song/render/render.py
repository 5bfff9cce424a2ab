"""``render(gaussians, camera) -> RenderOutput``: RGB-D images of Gaussian splats.

Backends behind one call, the same inputs and outputs:

- ``numba`` (CPU, the default here): the compiled tile rasterizer (:mod:`song.render._render_kernel`),
  after culling whole 256-Gaussian chunks by their boxes against the view frustum;
- ``gsplat`` (CUDA): gsplat's ``rasterization`` in ``RGB+ED`` mode (``pip install 'song[gpu]'``);
- ``reference``: the per-pixel numpy twin, for tests on tiny images;
- ``auto``: gsplat when torch sees a CUDA device and gsplat works (its CUDA code compiles on first use;
  a failure falls back to numba with one logged line), else numba.

Outputs: ``rgb`` (H, W, 3) uint8 (float colour clipped to [0, 1], rounded), ``depth`` (H, W) float32
expected planar depth z in metres (Σ wᵢ zᵢ / Σ wᵢ over the composited Gaussians, gsplat's "ED"), and
``alpha`` (H, W) float32 coverage. A pixel that sees nothing has alpha 0 and depth 0 (as in gsplat and
Habitat) and the background colour (black by default).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from song import plugins
from song.render import _render_kernel as kernel
from song.render.camera import Camera
from song.render.gaussians import CHUNK, GaussianSet, concat
from song.render.output import RenderOutput, to_uint8  # noqa: F401 (re-exported)

log = logging.getLogger(__name__)
EPS2D = 0.3  # px², the 2-D covariance dilation (gsplat's eps2d)
CULL_MARGIN_PX = 2.0  # chunks are kept when their box reaches this close to the image edge
BACKENDS = ("auto", "numba", "gsplat", "reference")  # the built-ins; plugins add more (song.plugins)
WHOLE_SET = 65_536  # sets this small skip chunk culling (bounds would cost more than they save)
BIN_PARTS = 8  # slices of the depth order sorted and binned in parallel (a fixed count: nothing depends on threads)


def visible_chunks(gaussians: GaussianSet, camera: Camera) -> np.ndarray:
    """Indices of the Gaussians whose chunk box is not wholly outside the view frustum (near/far, 4 sides).

    Sets of at most :data:`WHOLE_SET` Gaussians (posed avatars: a new set every step, not spatially
    sorted) are taken whole; the projection culls them one by one.
    """
    if len(gaussians) <= WHOLE_SET:
        return np.arange(len(gaussians))
    lo, hi = gaussians.chunk_bounds()
    if len(lo) == 0:
        return np.zeros(0, dtype=np.int64)
    corners = np.stack(
        [np.where(np.array([(k >> a) & 1 for a in range(3)], bool), hi, lo) for k in range(8)], axis=1
    )  # (C, 8, 3)
    cam = camera.to_camera(corners)
    x, y, z = cam[..., 0], cam[..., 1], cam[..., 2]
    m = CULL_MARGIN_PX
    outside = (
        (z < camera.near).all(axis=1)
        | (z > camera.far).all(axis=1)
        | (x * camera.fx > z * (camera.width - camera.cx + m)).all(axis=1)
        | (x * camera.fx < -z * (camera.cx + m)).all(axis=1)
        | (y * camera.fy > z * (camera.height - camera.cy + m)).all(axis=1)
        | (y * camera.fy < -z * (camera.cy + m)).all(axis=1)
    )
    chunks = np.flatnonzero(~outside)
    index = (chunks[:, None] * CHUNK + np.arange(CHUNK)[None, :]).ravel()
    return index[index < len(gaussians)]  # only the last chunk can be short


def _render_numba(
    sets: Sequence[GaussianSet], camera: Camera, background: np.ndarray, profile: dict[str, float] | None = None
) -> RenderOutput:
    return _render_numba_views([(sets, camera)], background, profile)[0]


@dataclass
class TileLists:
    """Projected Gaussians of one or several views, binned front to back per 16×16 tile.

    ``attr`` (N, N_ATTR) projected rows; ``order`` the visible rows by depth, view after view; ``rect``
    (N, 4) tile rectangles (view b's tile rows offset by b·tiles_y); ``offsets``/``ids`` the tile lists.
    """

    attr: np.ndarray
    order: np.ndarray
    rect: np.ndarray
    offsets: np.ndarray
    ids: np.ndarray
    width: int
    height: int
    tiles_x: int
    tiles_y: int


def tile_lists(views: Sequence[tuple[Sequence[GaussianSet], Camera]], lap=lambda name: None) -> TileLists:
    """Cull, project, sort and bin several views of one size (the numba backend's steps before compositing).

    ``lap(name)`` is called after each phase (``cull``, ``project``, ``sort``, ``bin``).
    """
    camera0 = views[0][1]
    width, height = int(camera0.width), int(camera0.height)
    tiles_x = (width + kernel.TILE - 1) // kernel.TILE
    tiles_y = (height + kernel.TILE - 1) // kernel.TILE
    selections = [[(s, visible_chunks(s, camera)) for s in sets if len(s)] for sets, camera in views]
    lap("cull")
    total = sum(len(sel) for view in selections for _, sel in view)
    if total >= 2**31:  # the tile lists hold row ids as int32
        raise ValueError(f"{total} Gaussians in one render call: at most 2**31 - 1")
    attr = np.empty((total, kernel.N_ATTR), dtype=np.float32)  # half the memory traffic of float64
    depth = np.empty(total)
    rect = np.empty((total, 4), dtype=np.int64)
    valid = np.zeros(total, dtype=np.bool_)
    offset, bounds = 0, [0]
    for b, ((_, camera), view) in enumerate(zip(views, selections, strict=True)):
        rot = np.ascontiguousarray(camera.rotation, dtype=np.float64)
        trans = np.ascontiguousarray(camera.translation, dtype=np.float64)
        pos = np.ascontiguousarray(camera.position, dtype=np.float64)
        for s, sel in view:
            if len(sel):
                kernel.project_kernel(
                    s.means, s.quats, s.scales, s.opacities, s.log_alpha_range(), s.sh, s.sh_degree, sel, rot, trans,
                    pos, float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy), width, height,
                    float(camera.near), float(camera.far), EPS2D, offset, b * tiles_y, attr, depth, rect, valid,
                )  # fmt: skip
            offset += len(sel)
        bounds.append(offset)
    lap("project")
    # each camera's visible Gaussians by depth (ties by input order), the cameras one after another
    order = np.concatenate(
        [
            kernel.depth_order(lo + np.flatnonzero(valid[lo:hi]), depth, BIN_PARTS)
            for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)
        ]
    )
    lap("sort")
    offsets, ids = kernel.bin_kernel(order, rect, tiles_x, tiles_y * len(views), BIN_PARTS)
    lap("bin")
    return TileLists(attr, order, rect, offsets, ids, width, height, tiles_x, tiles_y)


def _render_numba_views(
    views: Sequence[tuple[Sequence[GaussianSet], Camera]],
    background: np.ndarray,
    profile: dict[str, float] | None = None,
) -> list[RenderOutput]:
    """Several views (each its Gaussian sets and camera; one size), each image equal to that view alone.

    One projection buffer, one binning and one parallel compositing loop over every camera's tiles.
    """
    clock = [time.perf_counter()]

    def lap(name: str) -> None:
        if profile is not None:
            now = time.perf_counter()
            profile[name] = profile.get(name, 0.0) + now - clock[0]
            clock[0] = now

    t = tile_lists(views, lap)
    out_rgb = np.empty((len(views), t.height, t.width, 3), dtype=np.float32)
    out_depth = np.empty((len(views), t.height, t.width), dtype=np.float32)
    out_alpha = np.empty((len(views), t.height, t.width), dtype=np.float32)
    kernel.composite_kernel(t.offsets, t.ids, t.attr, t.width, t.height, t.tiles_x, t.tiles_y, background, out_rgb,
                            out_depth, out_alpha)  # fmt: skip
    lap("composite")
    return [RenderOutput(to_uint8(out_rgb[b]), out_depth[b], out_alpha[b], out_rgb[b]) for b in range(len(views))]


def _render_reference(sets: Sequence[GaussianSet], camera: Camera, background: np.ndarray) -> RenderOutput:
    from song.render._render_reference import render_reference

    rgb, depth, alpha = render_reference(concat(list(sets)), camera, tuple(background), EPS2D)
    return RenderOutput(to_uint8(rgb), depth.astype(np.float32), alpha.astype(np.float32), rgb.astype(np.float32))


_GSPLAT_STATE: dict[str, str] = {}  # "error" once gsplat failed in this process; "checked": the answer


def gsplat_available() -> str:
    """Why the gsplat backend cannot run here (one line), or the empty string when it can.

    Asked once per process (asking torch for a CUDA device took ~5 ms, every step of the closed loop).
    """
    if "error" in _GSPLAT_STATE:
        return _GSPLAT_STATE["error"]
    if "checked" not in _GSPLAT_STATE:
        _GSPLAT_STATE["checked"] = _gsplat_check()
    return _GSPLAT_STATE["checked"]


def _gsplat_check() -> str:
    try:
        import torch
    except ImportError:
        return "torch is not installed"
    if not torch.cuda.is_available():
        return "no CUDA device"
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return "gsplat is not installed (pip install 'song[gpu]')"
    return ""


def _gsplat_failed(exc: Exception) -> None:
    """Remember (and say once) that gsplat failed here: ``auto`` renders with numba from now on."""
    _GSPLAT_STATE["error"] = f"gsplat failed ({type(exc).__name__}: {exc}); rendering with numba on the CPU"
    log.warning(_GSPLAT_STATE["error"])


def _render_gsplat(sets: Sequence[GaussianSet], camera: Camera, background: np.ndarray, profile=None) -> RenderOutput:
    from song.render.gsplat_backend import render_gsplat

    return render_gsplat(sets, camera, background, EPS2D)


plugins.add("render_backend", "numba", _render_numba)
plugins.add("render_backend", "gsplat", _render_gsplat)
plugins.add("render_backend", "reference", lambda sets, camera, background, profile=None: _render_reference(
    sets, camera, background))  # fmt: skip


def resolve_backend(backend: str) -> str:
    """The backend that ``backend`` means here (``auto`` → gsplat when usable, else numba).

    Any other name is a ``render_backend`` plugin (:mod:`song.plugins`): ``fn(sets, camera, background,
    profile) -> RenderOutput`` for a list of :class:`GaussianSet`, a :class:`Camera`, an RGB background
    in [0, 1] and an optional per-phase timing dict.
    """
    if backend == "auto":
        return "gsplat" if not gsplat_available() else "numba"
    plugins.check_name("render_backend", backend, extra=("auto",))
    return backend


def render(
    gaussians: GaussianSet | Sequence[GaussianSet],
    camera: Camera,
    backend: str = "auto",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    profile: dict[str, float] | None = None,
) -> RenderOutput:
    """Render one view of one or several Gaussian sets (a scene and the posed avatars, composited together).

    Args:
        gaussians: a :class:`GaussianSet` or a sequence of them (rendered as one set).
        camera: the view (:func:`song.render.camera.robot_camera` for a robot).
        backend: ``auto`` | ``numba`` | ``gsplat`` | ``reference``.
        background: RGB in [0, 1] behind everything.
        profile: when given (numba backend), seconds spent per phase are added to it under ``cull``,
            ``project``, ``sort``, ``bin`` and ``composite``.

    Returns:
        :class:`RenderOutput` (rgb uint8, depth float32 m, alpha float32).
    """
    sets = [gaussians] if isinstance(gaussians, GaussianSet) else list(gaussians)
    bg = np.asarray(background, dtype=np.float64).reshape(3)
    name = resolve_backend(backend)
    if name == "gsplat" and backend == "auto":
        try:
            return _render_gsplat(sets, camera, bg)
        except Exception as exc:  # CUDA compile or runtime failure: fall back once, say so
            _gsplat_failed(exc)
            name = "numba"
    return plugins.lookup("render_backend", name)(sets, camera, bg, profile)


def render_views(
    views: Sequence[tuple[GaussianSet | Sequence[GaussianSet], Camera]],
    backend: str = "auto",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
    profile: dict[str, float] | None = None,
) -> list[RenderOutput]:
    """Several views, each its own Gaussian sets and camera (the robots of a vector env, in their scenes).

    The numba backend renders them in one pass: one projection buffer, one binning and one parallel
    compositing loop over the tiles of every camera, so small images keep both cores busy and the
    per-call overhead is paid once. Other backends render one view after another. Each output equals
    :func:`render` of that view alone, pixel for pixel.

    Raises:
        ValueError: cameras of different sizes or clip planes.
    """
    views = [([g] if isinstance(g, GaussianSet) else list(g), camera) for g, camera in views]
    if len({(c.width, c.height, c.near, c.far) for _, c in views}) > 1:
        raise ValueError("render_views: every camera must have the same size and clip planes")
    if not views:
        return []
    if resolve_backend(backend) == "numba":
        bg = np.asarray(background, dtype=np.float64).reshape(3)
        return _render_numba_views(views, bg, profile)
    return [render(sets, camera, backend, background, profile) for sets, camera in views]


def render_batch(
    gaussians: GaussianSet | Sequence[GaussianSet],
    cameras: Sequence[Camera],
    backend: str = "auto",
    background: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> list[RenderOutput]:
    """The same Gaussians seen by several cameras of one size (the views of a vector env's robots).

    gsplat renders them in one call (its batched ``viewmats``); numba in one pass (:func:`render_views`).
    Each output equals :func:`render` of that camera alone.

    Raises:
        ValueError: cameras of different sizes or clip planes.
    """
    sets = [gaussians] if isinstance(gaussians, GaussianSet) else list(gaussians)
    if len({(c.width, c.height, c.near, c.far) for c in cameras}) > 1:
        raise ValueError("render_batch: every camera must have the same size and clip planes")
    if not cameras:
        return []
    if resolve_backend(backend) == "gsplat":
        from song.render.gsplat_backend import render_gsplat_batch

        bg = np.asarray(background, dtype=np.float64).reshape(3)
        try:
            return render_gsplat_batch(sets, cameras, bg, EPS2D)
        except Exception as exc:
            if backend != "auto":
                raise
            _gsplat_failed(exc)
            backend = "numba"
    return render_views([(sets, camera) for camera in cameras], backend, background)
