"""A fake ``kimodo`` package with the real public signatures (nv-tlabs/kimodo, March 2026).

It checks what the adapter hands it and returns SOMA-77-shaped outputs: a T-posed body whose root
follows the dense root-2D constraint (Kimodo frame: Y up, heading θ = atan2(dx, dz)), with a known
root offset so that alignment has something to remove. Install it with :func:`install`.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import math
import os
import sys
import types
from pathlib import Path

import numpy as np
import torch

SOMA77 = (
    [
        "Hips",
        "Spine1",
        "Spine2",
        "Chest",
        "Neck1",
        "Neck2",
        "Head",
        "HeadEnd",
        "Jaw",
        "LeftEye",
        "RightEye",
        "LeftShoulder",
        "LeftArm",
        "LeftForeArm",
        "LeftHand",
    ]
    + [f"LeftHandFinger{i}" for i in range(24)]
    + ["RightShoulder", "RightArm", "RightForeArm", "RightHand"]
    + [f"RightHandFinger{i}" for i in range(24)]
    + [
        "LeftLeg",
        "LeftShin",
        "LeftFoot",
        "LeftToeBase",
        "LeftToeEnd",
        "RightLeg",
        "RightShin",
        "RightFoot",
        "RightToeBase",
        "RightToeEnd",
    ]
)
assert len(SOMA77) == 77
FAKE_HIPS_HEIGHT = 1.0  # hips above the lowest neutral joint (toe end), m
ROOT_OFFSET = np.array([0.03, -0.02])  # Kimodo-frame (X, Z) bias added to the generated root, m


class Skeleton:
    def __init__(self, name: str, names: list[str]) -> None:
        self.name = name
        self.bone_order_names = names
        neutral = np.zeros((len(names), 3), dtype=np.float32)
        if "LeftToeEnd" in names:
            neutral[names.index("LeftToeEnd")] = (0.1, -FAKE_HIPS_HEIGHT, 0.18)
            neutral[names.index("RightToeEnd")] = (-0.1, -FAKE_HIPS_HEIGHT, 0.18)
        self.neutral_joints = torch.from_numpy(neutral)


class Root2DConstraintSet:
    name = "root2d"

    def __init__(self, skeleton, frame_indices, smooth_root_2d, to_crop: bool = False, global_root_heading=None):
        assert len(smooth_root_2d) == len(frame_indices)
        self.skeleton = skeleton
        self.frame_indices = frame_indices
        self.smooth_root_2d = smooth_root_2d
        self.global_root_heading = global_root_heading


class Model:
    def __init__(self, text_encoder, device) -> None:
        self.fps = 30.0
        self.skeleton = Skeleton("somaskel30", SOMA77[:30])
        self.output_skeleton = Skeleton("somaskel77", SOMA77)
        self.text_encoder = text_encoder
        self.device = device
        self.calls: list[dict] = []

    def __call__(
        self,
        prompts,
        num_frames,
        num_denoising_steps,
        multi_prompt=False,
        constraint_lst=[],  # noqa: B006 (the real signature)
        cfg_weight=[2.0, 2.0],  # noqa: B006
        num_samples=None,
        cfg_type=None,
        return_numpy=False,
        first_heading_angle=None,
        num_transition_frames=5,
        share_transition=True,
        percentage_transition_override=0.10,
        post_processing=False,
        root_margin=0.04,
        progress_bar=None,
    ) -> dict:
        feat, lengths = self.text_encoder(prompts)
        self.calls.append(
            {
                "prompts": list(prompts),
                "num_frames": list(num_frames),
                "steps": num_denoising_steps,
                "multi_prompt": multi_prompt,
                "constraint_lst": constraint_lst,
                "num_samples": num_samples,
                "first_heading_angle": first_heading_angle,
                "post_processing": post_processing,
                "return_numpy": return_numpy,
                "text_feat_shape": tuple(feat.shape),
                "text_lengths": list(lengths),
            }
        )
        if multi_prompt:
            samples = [(sum(num_frames), constraint_lst[0])]
        else:
            samples = [(n, group[0]) for n, group in zip(num_frames, constraint_lst, strict=True)]
        out = {"global_rot_mats": [], "root_positions": [], "posed_joints": [], "foot_contacts": []}
        length = max(n for n, _ in samples)
        for n, constraint in samples:
            xz = constraint.smooth_root_2d.numpy().astype(np.float64)[:n]
            cos_sin = constraint.global_root_heading.numpy().astype(np.float64)[:n]
            theta = np.arctan2(cos_sin[:, 1], cos_sin[:, 0])
            rot = np.zeros((length, 3, 3))
            rot[:n, 0, 0] = np.cos(theta)
            rot[:n, 0, 2] = np.sin(theta)
            rot[:n, 1, 1] = 1.0
            rot[:n, 2, 0] = -np.sin(theta)
            rot[:n, 2, 2] = np.cos(theta)
            rot[n:] = np.eye(3)
            root = np.zeros((length, 3))
            root[:n, 0] = xz[:, 0] + ROOT_OFFSET[0]
            root[:n, 2] = xz[:, 1] + ROOT_OFFSET[1]
            root[:, 1] = FAKE_HIPS_HEIGHT
            out["global_rot_mats"].append(np.repeat(rot[:, None], 77, axis=1))
            out["root_positions"].append(root)
            out["posed_joints"].append(np.repeat(root[:, None], 77, axis=1))
            out["foot_contacts"].append(np.zeros((length, 4), dtype=bool))
        return {k: np.stack(v).astype(np.float32) for k, v in out.items()}


def install(monkeypatch, checkpoint_dir: Path) -> types.SimpleNamespace:
    """Put the fake package into ``sys.modules`` and weights into ``checkpoint_dir``."""
    state = types.SimpleNamespace(models=[])
    pkg = types.ModuleType("kimodo")
    pkg.__path__ = []  # a package
    model_pkg = types.ModuleType("kimodo.model")
    model_pkg.__path__ = []
    registry = types.ModuleType("kimodo.model.registry")
    registry.MODEL_NAMES = {"kimodo-soma-rp": "nvidia/Kimodo-SOMA-RP-v1"}
    info = types.SimpleNamespace(display_name="Kimodo-SOMA-RP-v1", repo_id="nvidia/Kimodo-SOMA-RP-v1")
    registry.get_model_info = lambda short: info if short == "kimodo-soma-rp" else None
    registry.get_short_key_from_display_name = lambda name: "kimodo-soma-rp" if name == info.display_name else None
    loader = types.ModuleType("kimodo.model.load_model")
    loader.TEXT_ENCODER_PRESETS = {"llm2vec": {"target": "kimodo.model.LLM2VecEncoder", "kwargs": {}}}

    def load_model(modelname=None, device=None, eval_mode=True, default_family="Kimodo", return_resolved_name=False):
        assert os.environ.get("TEXT_ENCODER_MODE") == "local", "the adapter must not reach a text-encoder server"
        preset = loader.TEXT_ENCODER_PRESETS[os.environ["TEXT_ENCODER"]]
        module, _, cls = preset["target"].rpartition(".")
        encoder = getattr(importlib.import_module(module), cls)(**preset["kwargs"])
        folder = Path(os.environ["CHECKPOINT_DIR"]) / info.display_name
        assert (folder / "config.yaml").exists()
        model = Model(encoder, device)
        state.models.append(model)
        return (model, "kimodo-soma-rp") if return_resolved_name else model

    loader.load_model = load_model
    constraints = types.ModuleType("kimodo.constraints")
    constraints.Root2DConstraintSet = Root2DConstraintSet
    sanitize = types.ModuleType("kimodo.sanitize")
    sanitize.sanitize_texts = lambda texts: [" ".join(t.split()) for t in texts]
    pkg.load_model = load_model
    pkg.DEFAULT_MODEL = "kimodo-soma-rp"
    pkg.AVAILABLE_MODELS = ["kimodo-soma-rp"]
    spec = importlib.machinery.ModuleSpec("kimodo", loader=None, is_package=True)
    pkg.__spec__ = spec
    for name, module in {
        "kimodo": pkg,
        "kimodo.model": model_pkg,
        "kimodo.model.registry": registry,
        "kimodo.model.load_model": loader,
        "kimodo.constraints": constraints,
        "kimodo.sanitize": sanitize,
    }.items():
        monkeypatch.setitem(sys.modules, name, module)
    folder = checkpoint_dir / info.display_name
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "config.yaml").write_text("fake: true\n")
    monkeypatch.setenv("CHECKPOINT_DIR", str(checkpoint_dir))
    return state


def heading_from(constraint) -> np.ndarray:
    cos_sin = constraint.global_root_heading.numpy()
    return np.arctan2(cos_sin[:, 1], cos_sin[:, 0])


def angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a - b + math.pi) % (2 * math.pi) - math.pi
