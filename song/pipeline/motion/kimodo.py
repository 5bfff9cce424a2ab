"""Adapter for NVIDIA Kimodo (github.com/nv-tlabs/kimodo), the paper's motion generator.

Used when ``kimodo`` imports and the model's weights are already on disk (``CHECKPOINT_DIR/<model>``
or the Hugging Face cache with ``LOCAL_CACHE=true``); nothing is ever downloaded here.

- **Model**: ``kimodo.load_model(name, device=...)`` (partial names such as ``SOMA`` are resolved by
  Kimodo's registry). Kimodo encodes each prompt with LLM2Vec (Llama-3 8B) into one pooled (1, 4096)
  vector; we register a *text-encoder stand-in* (:class:`CachedTextEncoder`, a preset of
  ``kimodo.model.load_model.TEXT_ENCODER_PRESETS`` selected with ``TEXT_ENCODER_MODE=local``) that
  serves those vectors from disk, so the 8B encoder is needed once per prompt, offline, via
  :func:`store_prompt_embedding`. Prompts are keyed after :func:`sanitize_prompt`, which does exactly
  what Kimodo's ``sanitize_texts`` does (Kimodo sanitises before encoding).
- **No network**: ``HF_HUB_OFFLINE=1`` is set before anything imports ``huggingface_hub`` (which reads
  it only at import; if it was imported earlier its constant is set too), so a missing file raises
  instead of downloading.
- **Canonical frame** (Kimodo's): Y up, the body faces +Z at heading 0 and heading
  ``θ = atan2(dx, dz)``. Each track is translated so frame 0 is at the origin and rotated so its first
  heading is +Z; world ``(x, y, z)`` then maps to Kimodo ``(X, Y, Z) = (y', z, x')`` (``x'`` along the
  first heading). The root path is a dense ``Root2DConstraintSet`` (``smooth_root_2d`` = (X, Z) every
  frame, ``global_root_heading`` = (cos θ, sin θ)) with ``first_heading_angle = 0``; the output is
  mapped back by the inverse transform.
- **Batching**: tracks up to ``kimodo_max_frames`` (Kimodo's 10 s = 300 frames) are generated
  together, one sample each with its own constraint list; longer tracks use multi-prompt generation
  (the prompt repeated over near-equal segments, stitched by Kimodo's transitions). Kimodo generates
  every segment after the first with 5 + 10 % of the previous segment's frames of transition in
  front, so segments are planned so that each generated window stays within the limit
  (:func:`plan_segments`). Constraints are built by Kimodo's ``Root2DConstraintSet.from_dict``: frame
  indices on the CPU (its post-processing indexes CPU tensors with them), data on the model's device
  (its conditioning indexes the data with the indices moved there); the denoising steps are capped at
  the model's base step count (more would index past its schedule).
- **Retargeting**: SOMA's neutral pose is a T-pose facing +Z like ours facing +x, and Kimodo's global
  rotations are relative to it, so each of our 24 joints copies the global rotation of its mapped SOMA
  joint (conjugated into our frame); the pelvis height is scaled by the ratio of rest pelvis heights.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import importlib.util
import math
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from song.config import MotionConfig
from song.errors import MissingDependencyError, SongError
from song.geometry.fk import global_to_local
from song.geometry.rotations import matrix_to_quat, rot_z
from song.geometry.skeleton import JOINT_NAMES, rest_joints
from song.pipeline.motion.gait import style_for
from song.pipeline.motion.types import Motion, Trajectory, body_heading

ENCODER_PRESET = "song-cached"
# world-canonical (x' forward, y' left, z up) → Kimodo (X, Y up, Z forward): X = y', Y = z, Z = x'
M_WORLD_TO_KIMODO = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
SOMA_TO_OURS = {
    "pelvis": "Hips",
    "left_hip": "LeftLeg",
    "right_hip": "RightLeg",
    "spine1": "Spine1",
    "left_knee": "LeftShin",
    "right_knee": "RightShin",
    "spine2": "Spine2",
    "left_ankle": "LeftFoot",
    "right_ankle": "RightFoot",
    "spine3": "Chest",
    "left_foot": "LeftToeBase",
    "right_foot": "RightToeBase",
    "neck": "Neck1",
    "left_collar": "LeftShoulder",
    "right_collar": "RightShoulder",
    "head": "Head",
    "left_shoulder": "LeftArm",
    "right_shoulder": "RightArm",
    "left_elbow": "LeftForeArm",
    "right_elbow": "RightForeArm",
    "left_wrist": "LeftHand",
    "right_wrist": "RightHand",
    "left_hand": "LeftHand",
    "right_hand": "RightHand",
}


class MissingEmbeddingError(SongError):
    """A prompt has no cached embedding for the Kimodo text-encoder stand-in."""


def embedding_cache_dir(cfg: MotionConfig) -> Path:
    """Folder of cached prompt embeddings (config, ``$SONG_KIMODO_EMBEDDINGS`` or ``~/.cache/song``)."""
    if cfg.kimodo_embedding_cache:
        return Path(cfg.kimodo_embedding_cache).expanduser()
    env = os.environ.get("SONG_KIMODO_EMBEDDINGS")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "song" / "kimodo_embeddings"


def _embedding_path(cache_dir: Path, text: str) -> Path:
    return cache_dir / f"{hashlib.sha256(text.encode('utf-8')).hexdigest()}.npy"


FINAL_PUNCTUATION = ".!?\"])'"
TRANSITION_FRAMES, TRANSITION_SHARE = 5, 0.10  # Kimodo's multi-prompt transition (5 + 10 % of the previous)
LLM_DIM = 4096  # LLM2Vec's pooled prompt vector


def sanitize_prompt(text: str) -> str:
    """A prompt as Kimodo's ``sanitize_text`` leaves it (our own implementation of its rules).

    Whitespace collapsed; leading non-alphanumerics dropped; ``str.capitalize`` (first letter upper,
    the rest lower); trailing characters that are neither alphanumeric nor closing punctuation
    dropped; a period added unless it ends in ``.!?``; then every sentence (split at ``.``, ``!``,
    ``?`` in turn) stripped, its first character capitalised, and re-joined with the break and a space.
    """
    text = " ".join(text.split())
    if not text:
        return text
    start = next((i for i, c in enumerate(text) if c.isalnum()), len(text) - 1)
    text = text[start:].capitalize()
    end = next((i for i in range(len(text) - 1, -1, -1) if text[i].isalnum() or text[i] in FINAL_PUNCTUATION), 0)
    text = text[: end + 1]
    if text[-1] not in ".!?":
        text += "."
    for mark in ".!?":
        parts = [part.strip() for part in text.split(mark)]
        text = f"{mark} ".join(part[0].upper() + part[1:] if part else part for part in parts).strip()
    return text


def _sanitize(texts: list[str]) -> list[str]:
    return [sanitize_prompt(text) for text in texts]


def plan_segments(n_frames: int, max_frames: int) -> list[int]:
    """Near-equal segment lengths summing to ``n_frames`` whose generated windows stay ≤ ``max_frames``.

    The first window is its segment; every later one is its segment plus Kimodo's transition
    (5 + ⌊10 % of the previous segment⌋ frames).
    """
    largest = max(1, int((max_frames - TRANSITION_FRAMES) / (1.0 + TRANSITION_SHARE)))
    count = 1 if n_frames <= max_frames else math.ceil(n_frames / largest)
    base = n_frames // count
    return [base + (1 if i < n_frames % count else 0) for i in range(count)]


_LOADED: dict[tuple[str, str, str], tuple[Any, Any, str]] = {}  # (model, encoder cache, device) → loaded


def _offline() -> None:
    """``HF_HUB_OFFLINE=1`` for this process, before (or, if too late, also after) huggingface_hub's import."""
    import sys

    os.environ["HF_HUB_OFFLINE"] = "1"
    constants = sys.modules.get("huggingface_hub.constants")
    if constants is not None:
        constants.HF_HUB_OFFLINE = True


def _kimodo(name: str) -> Any:
    """Import a kimodo module with the hub offline."""
    _offline()
    return importlib.import_module(name)


def store_prompt_embedding(cache_dir: str | Path, prompt: str, embedding: np.ndarray) -> Path:
    """Cache one prompt's pooled LLM2Vec vector (4096,) or (1, 4096) for the stand-in encoder.

    Get it once, where the 8B encoder runs, from ``kimodo.model.LLM2VecEncoder()(prompt)``. The key is
    the prompt as Kimodo encodes it (after :func:`sanitize_prompt`).
    """
    import io

    from song.util import write_bytes_atomic

    embedding = np.asarray(embedding, dtype=np.float32)
    if embedding.ndim == 2 and embedding.shape[0] == 1:
        embedding = embedding[0]
    if embedding.shape != (LLM_DIM,):
        raise ValueError(f"embedding must be one pooled ({LLM_DIM},) vector per prompt, got {embedding.shape}")
    path = _embedding_path(Path(cache_dir), sanitize_prompt(prompt))
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.save(buffer, embedding)
    write_bytes_atomic(path, buffer.getvalue())
    return path


def has_prompt_embedding(cache_dir: str | Path, prompt: str) -> bool:
    """Whether :func:`store_prompt_embedding` cached ``prompt``."""
    return _embedding_path(Path(cache_dir), sanitize_prompt(prompt)).is_file()


class CachedTextEncoder:
    """Text-encoder stand-in with Kimodo's encoder call: ``(texts) -> (feat (B, 1, 4096), lengths [1] * B)``.

    LLM2Vec pools each prompt into one vector, so every "sequence" has length 1 (a single string gives
    ``(1, 4096)`` and ``1``, as Kimodo's encoder does).

    Args:
        cache_dir: folder written by :func:`store_prompt_embedding`.
    """

    def __init__(self, cache_dir: str, **_: Any) -> None:
        self.cache_dir = Path(cache_dir)
        self.device = "cpu"
        self.dtype = None
        self._memory: dict[str, np.ndarray] = {}

    def to(self, device: Any = None, dtype: Any = None) -> CachedTextEncoder:
        """Move to a device / dtype (the torch module protocol Kimodo calls)."""
        if device is not None:
            self.device = device
        if dtype is not None:
            self.dtype = dtype
        return self

    def _load(self, text: str) -> np.ndarray:
        if text not in self._memory:
            path = _embedding_path(self.cache_dir, text)
            if not path.exists():
                raise MissingEmbeddingError(
                    f"{path}: no cached Kimodo embedding for prompt {text!r}; encode it once with Kimodo's "
                    "LLM2VecEncoder and song.pipeline.motion.kimodo.store_prompt_embedding"
                )
            self._memory[text] = np.load(path).reshape(-1)
        return self._memory[text]

    def __call__(self, texts: str | list[str]) -> tuple[Any, Any]:
        """Encode prompts from the cache, as Kimodo's text encoder returns them."""
        import torch

        single = isinstance(texts, str)
        names = _sanitize([texts] if single else list(texts))  # idempotent: Kimodo sanitised already
        feat = np.stack([self._load(text) for text in names])[:, None, :]
        out = torch.from_numpy(feat).to(device=self.device)
        out = out if self.dtype is None else out.to(self.dtype)
        return (out[0], 1) if single else (out, [1] * len(names))


def _model_info(model_name: str) -> tuple[str, str, str]:
    """(short key, display name, Hugging Face repo id) of a Kimodo model name, partial names resolved."""
    registry = _kimodo("kimodo.model.registry")
    short = model_name
    if short not in registry.MODEL_NAMES:
        short = registry.get_short_key_from_display_name(model_name) or short
    if short not in registry.MODEL_NAMES and hasattr(registry, "resolve_model_name"):
        try:
            short = registry.resolve_model_name(model_name, "Kimodo")
        except ValueError:
            pass
    info = registry.get_model_info(short)
    if info is None:
        return short, model_name, ""
    return short, info.display_name, info.repo_id


def kimodo_checkpoint(model_name: str) -> Path | None:
    """Local folder of the model's weights (``config.yaml`` inside), or ``None``; never downloads."""
    short, display, repo_id = _model_info(model_name)
    root = os.environ.get("CHECKPOINT_DIR")
    if root:
        for name in (display, short):
            if (Path(root) / name / "config.yaml").exists():
                return Path(root) / name
    if repo_id:
        try:
            _offline()
            from huggingface_hub import try_to_load_from_cache
        except ImportError:
            return None
        found = try_to_load_from_cache(repo_id, "config.yaml")
        if isinstance(found, str):
            return Path(found).parent
    return None


def kimodo_availability(cfg: MotionConfig) -> str:
    """``""`` when Kimodo can run here with ``cfg``, else the reason it cannot (the fallback reason).

    Checks the package, the weights on disk, Kimodo's ``motion_correction`` extension when its
    post-processing is on, and the cached embedding of the prompt.
    """
    if importlib.util.find_spec("kimodo") is None:
        return "the kimodo package is not installed"
    try:
        if kimodo_checkpoint(cfg.kimodo_model) is None:
            return (
                f"no local weights for {cfg.kimodo_model} (set CHECKPOINT_DIR, or have them in the Hugging Face cache)"
            )
    except Exception as exc:  # a broken kimodo install must not break the stage
        return f"kimodo import failed: {type(exc).__name__}: {exc}"
    if cfg.kimodo_postprocess and importlib.util.find_spec("motion_correction") is None:
        return "Kimodo's motion_correction extension is not built (pip install -e MotionCorrection), or set motion.kimodo_postprocess=false"
    if not has_prompt_embedding(embedding_cache_dir(cfg), cfg.prompt):
        return f"no cached embedding of the prompt {sanitize_prompt(cfg.prompt)!r} in {embedding_cache_dir(cfg)}"
    return ""


@contextlib.contextmanager
def _environment(values: dict[str, str]) -> Iterator[None]:
    saved = {key: os.environ.get(key) for key in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def canonicalize(traj: Trajectory, t: np.ndarray) -> dict[str, np.ndarray]:
    """Kimodo-frame root path of ``traj`` sampled at times ``t`` (see the module docstring).

    Returns:
        ``root_2d (T, 2)`` Kimodo (X, Z) metres (frame 0 at the origin, first heading +Z),
        ``heading (T,)`` radians ``θ = atan2(dx, dz)``, ``origin (2,)`` world xy and ``yaw0`` radians.
    """
    x = np.interp(t, traj.t, traj.xy[:, 0])
    y = np.interp(t, traj.t, traj.xy[:, 1])
    yaw = np.interp(t, traj.t, body_heading(traj.yaw, traj.t))
    origin = np.array([x[0], y[0]])
    yaw0 = float(yaw[0])
    c, s = math.cos(-yaw0), math.sin(-yaw0)
    fwd = c * (x - origin[0]) - s * (y - origin[1])
    left = s * (x - origin[0]) + c * (y - origin[1])
    heading = yaw - yaw0  # a body facing world yaw ψ faces Kimodo (dx, dz) = (sin, cos)(ψ − ψ0)
    return {"root_2d": np.stack([left, fwd], axis=-1), "heading": heading, "origin": origin, "yaw0": np.array(yaw0)}


def _quiet(iterable: Any) -> Any:
    return iterable


class KimodoGenerator:
    """Kimodo-backed :class:`~song.pipeline.motion.generators.MotionGenerator` (module docstring)."""

    name = "kimodo"

    def __init__(self, cfg: MotionConfig | None = None, device: str | None = None) -> None:
        self.cfg = cfg or MotionConfig()
        self.device = device
        self._model: Any = None
        self._resolved = self.cfg.kimodo_model

    def load(self) -> Any:
        """The model, with the cached-embedding text encoder (no network, no LLM); loaded once per process.

        A worker process keeps the last model it loaded, so the scenes it synthesises share one load
        (Kimodo's weights take seconds to minutes to load).
        """
        if self._model is not None:
            return self._model
        try:
            import torch
        except ImportError:
            raise MissingDependencyError("torch", "torch") from None
        kimodo = _kimodo("kimodo")
        loader = _kimodo("kimodo.model.load_model")
        checkpoint = kimodo_checkpoint(self.cfg.kimodo_model)
        loader.TEXT_ENCODER_PRESETS[ENCODER_PRESET] = {
            "target": f"{CachedTextEncoder.__module__}.{CachedTextEncoder.__name__}",
            "kwargs": {"cache_dir": str(embedding_cache_dir(self.cfg))},
        }
        env = {"TEXT_ENCODER_MODE": "local", "TEXT_ENCODER": ENCODER_PRESET}
        if checkpoint is not None and not os.environ.get("CHECKPOINT_DIR"):
            env["LOCAL_CACHE"] = "true"
        device = self.device or ("cuda:0" if torch.cuda.is_available() else "cpu")
        key = (self.cfg.kimodo_model, str(embedding_cache_dir(self.cfg)), str(device))
        cached = _LOADED.get(key)
        if cached is not None and cached[0] is kimodo:  # the same kimodo module: the model is still valid
            _, self._model, self._resolved = cached
        else:
            with _environment(env):
                self._model, self._resolved = kimodo.load_model(
                    self.cfg.kimodo_model, device=device, default_family="Kimodo", return_resolved_name=True
                )
            _LOADED.clear()  # one model per process: a worker keeps it across scenes
            _LOADED[key] = (kimodo, self._model, self._resolved)
        self.device = device
        return self._model

    def _constraint(self, model: Any, canon: dict[str, np.ndarray]) -> Any:
        """The root path as Kimodo's own ``Root2DConstraintSet.from_dict`` builds it.

        That puts the frame indices on the CPU (Kimodo's post-processing indexes CPU buffers with them)
        and the data on the skeleton's device, the model's: ``create_conditions`` moves the indices to
        the model's device and indexes the data with them, which fails on a GPU for CPU data.
        """
        constraints = _kimodo("kimodo.constraints")
        n = len(canon["root_2d"])
        heading = np.stack([np.cos(canon["heading"]), np.sin(canon["heading"])], axis=-1)
        return constraints.Root2DConstraintSet.from_dict(
            model.skeleton,
            {
                "frame_indices": np.arange(n, dtype=np.int64),
                "smooth_root_2d": np.asarray(canon["root_2d"], dtype=np.float32),
                "global_root_heading": heading.astype(np.float32),
            },
        )

    def generate(
        self, trajectories: Sequence[Trajectory], activities: Sequence[str], seeds: Sequence[int]
    ) -> list[Motion]:
        """Batched generation; see the module docstring for the frames and the retargeting."""
        import torch

        model = self.load()
        fps = float(model.fps)
        prompt = self.cfg.prompt
        jobs = []
        for traj, activity, seed in zip(trajectories, activities, seeds, strict=True):
            n = max(2, int(round((traj.t[-1] - traj.t[0]) * fps)) + 1)
            t = traj.t[0] + np.arange(n) / fps
            jobs.append((traj, activity, int(seed), t, canonicalize(traj, t)))
        motions: list[Motion | None] = [None] * len(jobs)
        short = [i for i, job in enumerate(jobs) if len(job[3]) <= self.cfg.kimodo_max_frames]
        long = [i for i, job in enumerate(jobs) if len(job[3]) > self.cfg.kimodo_max_frames]
        base_steps = getattr(getattr(model, "diffusion", None), "num_base_steps", None)
        self._steps = min(self.cfg.kimodo_steps, int(base_steps)) if base_steps else self.cfg.kimodo_steps
        common = {
            "num_denoising_steps": self._steps,
            "post_processing": self.cfg.kimodo_postprocess,
            "return_numpy": True,
            "progress_bar": _quiet,
        }
        for start in range(0, len(short), self.cfg.kimodo_batch_size):
            batch = short[start : start + self.cfg.kimodo_batch_size]
            seed = jobs[batch[0]][2]
            torch.manual_seed(seed % (2**63))
            output = model(
                [prompt] * len(batch),
                [len(jobs[i][3]) for i in batch],
                constraint_lst=[[self._constraint(model, jobs[i][4])] for i in batch],
                num_samples=len(batch),
                first_heading_angle=torch.zeros(len(batch)),
                **common,
            )
            for k, i in enumerate(batch):
                motions[i] = self._to_motion(model, output, k, jobs[i], seed, segments=1)
        for i in long:
            seed = jobs[i][2]
            torch.manual_seed(seed % (2**63))
            lengths = plan_segments(len(jobs[i][3]), self.cfg.kimodo_max_frames)
            output = model(
                [prompt] * len(lengths),
                lengths,
                multi_prompt=True,
                constraint_lst=[self._constraint(model, jobs[i][4])],
                num_samples=1,
                first_heading_angle=torch.zeros(1),
                **common,
            )
            motions[i] = self._to_motion(model, output, 0, jobs[i], seed, segments=len(lengths))
        return [m for m in motions if m is not None]

    def _to_motion(self, model: Any, output: dict, k: int, job: tuple, seed: int, segments: int) -> Motion:
        traj, activity, own_seed, t, canon = job
        n = len(t)
        skeleton = getattr(model, "output_skeleton", model.skeleton)
        names = list(skeleton.bone_order_names)
        missing = [soma for soma in SOMA_TO_OURS.values() if soma not in names]
        if missing:
            raise SongError(f"Kimodo skeleton {getattr(skeleton, 'name', '?')} lacks SOMA joints {missing[:3]}")
        index = [names.index(SOMA_TO_OURS[name]) for name in JOINT_NAMES]
        rots = np.asarray(output["global_rot_mats"])[k, :n][:, index].astype(np.float64)
        root_k = np.asarray(output["root_positions"])[k, :n].astype(np.float64)
        m = M_WORLD_TO_KIMODO
        undo = rot_z(float(canon["yaw0"]))
        glob = undo @ m.T @ rots @ m
        style = style_for(own_seed, self.cfg)
        rest = rest_joints(style.height_m)
        neutral = skeleton.neutral_joints
        neutral = np.asarray(neutral.detach().cpu() if hasattr(neutral, "detach") else neutral, dtype=np.float64)
        soma_pelvis = neutral[names.index("Hips"), 1] - neutral[:, 1].min()
        root = (undo @ (m.T @ root_k.T)).T
        root[:, :2] += canon["origin"]
        root[:, 2] = root_k[:, 1] * rest[0, 2] / soma_pelvis
        return Motion(
            ped_id=traj.ped_id,
            t=t,
            frame=np.round(t * traj.fps).astype(np.int32),
            height_m=style.height_m,
            rest_joints=rest,
            local_quats=matrix_to_quat(global_to_local(glob)),
            root_pos=root,
            info={
                "name": "kimodo",
                "model": str(self._resolved),
                "seed": int(own_seed),
                "batch_seed": int(seed),
                "sample_index": int(k),
                "segments": int(segments),
                "prompt": self.cfg.prompt,
                "activity": activity,
                "denoising_steps": self._steps,
                "kimodo_postprocess": self.cfg.kimodo_postprocess,
                "canonical": {"origin": canon["origin"].round(6).tolist(), "yaw0": round(float(canon["yaw0"]), 6)},
                "walk_ratio_m_s": round(style.walk_ratio, 6),
                "style": style.to_json(),
            },
        )
