"""Adapter for NVIDIA Kimodo (github.com/nv-tlabs/kimodo), the paper's motion generator.

Used when ``kimodo`` imports and the model's weights are already on disk (``CHECKPOINT_DIR/<model>``
or the Hugging Face cache with ``LOCAL_CACHE=true``); nothing is ever downloaded here.

- **Model**: ``kimodo.load_model(name, device=...)``. Kimodo encodes prompts with LLM2Vec (Llama-3
  8B); we register a *text-encoder stand-in* (:class:`CachedTextEncoder`, a preset of
  ``kimodo.model.load_model.TEXT_ENCODER_PRESETS`` selected with ``TEXT_ENCODER_MODE=local``) that
  serves cached prompt embeddings from disk, so the 8B encoder is needed once per prompt, offline,
  via :func:`store_prompt_embedding`.
- **Canonical frame** (Kimodo's): Y up, the body faces +Z at heading 0 and heading
  ``θ = atan2(dx, dz)``. Each track is translated so frame 0 is at the origin and rotated so its first
  heading is +Z; world ``(x, y, z)`` then maps to Kimodo ``(X, Y, Z) = (y', z, x')`` (``x'`` along the
  first heading). The root path is a dense ``Root2DConstraintSet`` (``smooth_root_2d`` = (X, Z) every
  frame, ``global_root_heading`` = (cos θ, sin θ)) with ``first_heading_angle = 0``; the output is
  mapped back by the inverse transform.
- **Batching**: tracks up to ``kimodo_max_frames`` are generated together, one sample each with its
  own constraint list; longer tracks use multi-prompt generation (the prompt repeated over near-equal
  segments ≤ the limit, stitched by Kimodo's transitions).
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


def _sanitize(texts: list[str]) -> list[str]:
    try:
        from kimodo.sanitize import sanitize_texts
    except ImportError:
        return [" ".join(text.split()) for text in texts]
    return list(sanitize_texts(texts))


def store_prompt_embedding(cache_dir: str | Path, prompt: str, embedding: np.ndarray) -> Path:
    """Cache one prompt's token embeddings ``(L, D)`` (e.g. from Kimodo's LLM2VecEncoder) for the stand-in.

    The key is the prompt as Kimodo passes it to its encoder (after ``sanitize_texts``).
    """
    from song.util import write_bytes_atomic

    embedding = np.asarray(embedding, dtype=np.float32)
    if embedding.ndim != 2:
        raise ValueError(f"embedding must be (tokens, dim), got {embedding.shape}")
    path = _embedding_path(Path(cache_dir), _sanitize([prompt])[0])
    path.parent.mkdir(parents=True, exist_ok=True)
    import io

    buffer = io.BytesIO()
    np.save(buffer, embedding)
    write_bytes_atomic(path, buffer.getvalue())
    return path


class CachedTextEncoder:
    """Text-encoder stand-in with Kimodo's encoder call signature: ``(texts) -> (feat, lengths)``.

    ``feat`` is a ``(B, L_max, D)`` float tensor zero-padded per prompt, ``lengths`` the token counts.

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
                    f"{path}: no cached Kimodo embedding for prompt {text!r}; "
                    "encode it once with Kimodo's LLM2VecEncoder and song.pipeline.motion.kimodo.store_prompt_embedding"
                )
            self._memory[text] = np.load(path)
        return self._memory[text]

    def __call__(self, texts: str | list[str]) -> tuple[Any, list[int]]:
        """Encode prompts from the cache: (embeddings, lengths), as Kimodo's text encoder returns."""
        import torch

        texts = _sanitize([texts] if isinstance(texts, str) else list(texts))  # idempotent
        arrays = [self._load(text) for text in texts]
        lengths = [len(a) for a in arrays]
        feat = np.zeros((len(arrays), max(lengths), arrays[0].shape[1]), dtype=np.float32)
        for i, a in enumerate(arrays):
            feat[i, : len(a)] = a
        out = torch.from_numpy(feat).to(device=self.device)
        return (out if self.dtype is None else out.to(self.dtype)), lengths


def _model_info(model_name: str) -> tuple[str, str, str]:
    """(short key, display name, Hugging Face repo id) of a Kimodo model name."""
    registry = importlib.import_module("kimodo.model.registry")
    short = model_name
    if short not in registry.MODEL_NAMES:
        short = registry.get_short_key_from_display_name(model_name) or model_name
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
    if os.environ.get("LOCAL_CACHE", "false").lower() == "true" and repo_id:
        try:
            from huggingface_hub import try_to_load_from_cache
        except ImportError:
            return None
        found = try_to_load_from_cache(repo_id, "config.yaml")
        if isinstance(found, str):
            return Path(found).parent
    return None


def kimodo_availability(model_name: str) -> str:
    """``""`` when Kimodo can run here, else the reason it cannot (recorded as the fallback reason)."""
    if importlib.util.find_spec("kimodo") is None:
        return "the kimodo package is not installed"
    try:
        if kimodo_checkpoint(model_name) is None:
            return f"no local weights for {model_name} (set CHECKPOINT_DIR, or LOCAL_CACHE=true with a HF cache)"
    except Exception as exc:  # a broken kimodo install must not break the stage
        return f"kimodo import failed: {type(exc).__name__}: {exc}"
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


def _segments(n_frames: int, max_frames: int) -> list[int]:
    count = max(1, math.ceil(n_frames / max_frames))
    base = n_frames // count
    return [base + (1 if i < n_frames % count else 0) for i in range(count)]


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
        """Load the model once, with the cached-embedding text encoder (no network, no LLM)."""
        if self._model is not None:
            return self._model
        try:
            import torch
        except ImportError:
            raise MissingDependencyError("torch", "kimodo") from None
        kimodo = importlib.import_module("kimodo")
        loader = importlib.import_module("kimodo.model.load_model")
        checkpoint = kimodo_checkpoint(self.cfg.kimodo_model)
        loader.TEXT_ENCODER_PRESETS[ENCODER_PRESET] = {
            "target": f"{CachedTextEncoder.__module__}.{CachedTextEncoder.__name__}",
            "kwargs": {"cache_dir": str(embedding_cache_dir(self.cfg))},
        }
        env = {"TEXT_ENCODER_MODE": "local", "TEXT_ENCODER": ENCODER_PRESET, "HF_HUB_OFFLINE": "1"}
        if checkpoint is not None and not os.environ.get("CHECKPOINT_DIR"):
            env["LOCAL_CACHE"] = "true"
        device = self.device or ("cuda:0" if torch.cuda.is_available() else "cpu")
        with _environment(env):
            self._model, self._resolved = kimodo.load_model(
                self.cfg.kimodo_model, device=device, default_family="Kimodo", return_resolved_name=True
            )
        self.device = device
        return self._model

    def _constraint(self, model: Any, canon: dict[str, np.ndarray]) -> Any:
        import torch

        constraints = importlib.import_module("kimodo.constraints")
        n = len(canon["root_2d"])
        device = getattr(model, "device", None) or "cpu"
        heading = np.stack([np.cos(canon["heading"]), np.sin(canon["heading"])], axis=-1)
        return constraints.Root2DConstraintSet(
            model.skeleton,
            torch.arange(n, device=device),
            torch.as_tensor(canon["root_2d"], dtype=torch.float32, device=device),
            global_root_heading=torch.as_tensor(heading, dtype=torch.float32, device=device),
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
        common = {
            "num_denoising_steps": self.cfg.kimodo_steps,
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
            lengths = _segments(len(jobs[i][3]), self.cfg.kimodo_max_frames)
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
                "denoising_steps": self.cfg.kimodo_steps,
                "kimodo_postprocess": self.cfg.kimodo_postprocess,
                "canonical": {"origin": canon["origin"].round(6).tolist(), "yaw0": round(float(canon["yaw0"]), 6)},
                "walk_ratio_m_s": round(style.walk_ratio, 6),
                "style": style.to_json(),
            },
        )
