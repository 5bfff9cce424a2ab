"""The fake model: checks what it is given the way the real one would fail, returns SOMA-77 outputs."""

from collections import defaultdict

import numpy as np
import torch

from kimodo.fake_device import index, on
from kimodo.sanitize import sanitize_texts

SOMA77 = (
    ["Hips", "Spine1", "Spine2", "Chest", "Neck1", "Neck2", "Head", "HeadEnd", "Jaw", "LeftEye", "RightEye",
     "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"]
    + [f"LeftHandFinger{i}" for i in range(24)]
    + ["RightShoulder", "RightArm", "RightForeArm", "RightHand"]
    + [f"RightHandFinger{i}" for i in range(24)]
    + ["LeftLeg", "LeftShin", "LeftFoot", "LeftToeBase", "LeftToeEnd",
       "RightLeg", "RightShin", "RightFoot", "RightToeBase", "RightToeEnd"]
)  # fmt: skip
SOMA30 = SOMA77[:15] + ["RightShoulder", "RightArm", "RightForeArm", "RightHand"] + SOMA77[-10:] + ["Spine3"]
assert len(SOMA77) == 77 and len(SOMA30) == 30
FAKE_HIPS_HEIGHT = 1.0  # hips above the lowest neutral joint (toe end), m
ROOT_OFFSET = np.array([0.03, -0.02])  # Kimodo-frame (X, Z) bias added to the generated root, m
MAX_WINDOW = 300  # Kimodo's 10 s at 30 FPS per generated window
BASE_STEPS = 50  # this fake's diffusion schedule (the real value comes from the model's config)
LLM_DIM = 4096


class Skeleton:
    def __init__(self, name, names, device="cpu"):
        self.device = device  # Kimodo's: the device of its neutral joints, which follow the model
        self.name = name
        self.bone_order_names = names
        neutral = np.zeros((len(names), 3), dtype=np.float32)
        if "LeftToeEnd" in names:
            neutral[names.index("LeftToeEnd")] = (0.1, -FAKE_HIPS_HEIGHT, 0.18)
            neutral[names.index("RightToeEnd")] = (-0.1, -FAKE_HIPS_HEIGHT, 0.18)
        self.neutral_joints = torch.from_numpy(neutral)


class Diffusion:
    def __init__(self, num_base_steps):
        self.num_base_steps = num_base_steps
        self.timesteps = torch.arange(num_base_steps)

    def space_timesteps(self, steps):
        stride = self.num_base_steps // steps if steps <= self.num_base_steps else 0
        return self.timesteps[torch.arange(steps) * max(stride, 1)]  # IndexError past the schedule


def _postprocess(constraint, n):
    """As Kimodo's post-processing: CPU buffers indexed with the constraint's frame indices."""
    hips = torch.zeros((n, 3))
    index(hips, constraint.frame_indices)  # CPU buffers, so the indices must be on the CPU
    hips[constraint.frame_indices, 0] = constraint.smooth_root_2d[:, 0].cpu()


def _create_conditions(constraints, device):
    """As Kimodo's ``create_conditions``: indices moved to the model's device index the constraint data."""
    index_dict, data_dict = defaultdict(list), defaultdict(list)
    for constraint in constraints:
        constraint.update_constraints(data_dict, index_dict)
    for name, indices in index_dict.items():
        for data, frames in zip(data_dict[name], indices, strict=True):
            first = on(torch.arange(len(frames)), device)  # torch.unique's inverse lives with the moved indices
            index(data, first)


class Model:
    def __init__(self, text_encoder, device):
        self.fps = 30.0
        where = str(device) if device is not None else "cpu"
        self.skeleton = Skeleton("somaskel30", SOMA30, where)
        self.output_skeleton = Skeleton("somaskel77", SOMA77, where)
        self.text_encoder = text_encoder
        self.device = device
        self.diffusion = Diffusion(BASE_STEPS)
        self.calls = []

    def _encode(self, prompts):
        texts = sanitize_texts(list(prompts))
        feat, lengths = self.text_encoder(texts)
        assert tuple(feat.shape) == (len(texts), 1, LLM_DIM) and list(lengths) == [1] * len(texts), (
            feat.shape, lengths)  # fmt: skip
        return texts, feat

    def __call__(self, prompts, num_frames, num_denoising_steps, multi_prompt=False, constraint_lst=[],  # noqa: B006
                 cfg_weight=[2.0, 2.0], num_samples=None, cfg_type=None, return_numpy=False,  # noqa: B006
                 first_heading_angle=None, num_transition_frames=5, share_transition=True,
                 percentage_transition_override=0.10, post_processing=False, root_margin=0.04,
                 progress_bar=None):  # fmt: skip
        texts, feat = self._encode(prompts)
        self.diffusion.space_timesteps(num_denoising_steps)
        if multi_prompt:
            windows = [num_frames[0]] + [
                n + num_transition_frames + int(prev * percentage_transition_override)
                for prev, n in zip(num_frames[:-1], num_frames[1:], strict=False)
            ]
        else:
            windows = list(num_frames)
        if max(windows) > MAX_WINDOW:
            raise ValueError(f"a generated window of {max(windows)} frames exceeds {MAX_WINDOW}")
        self.calls.append({"prompts": list(prompts), "texts": texts, "num_frames": list(num_frames),
                           "windows": windows, "steps": num_denoising_steps, "multi_prompt": multi_prompt,
                           "constraint_lst": constraint_lst, "num_samples": num_samples,
                           "first_heading_angle": first_heading_angle, "post_processing": post_processing,
                           "return_numpy": return_numpy, "text_feat_shape": tuple(feat.shape)})  # fmt: skip
        if multi_prompt:
            samples = [(sum(num_frames), constraint_lst[0])]
        else:
            samples = [(n, group[0]) for n, group in zip(num_frames, constraint_lst, strict=True)]
        for _, constraint in samples:
            _create_conditions([constraint], self.skeleton.device)
        if post_processing:
            for n, constraint in samples:
                _postprocess(constraint, n)
        out = {"global_rot_mats": [], "root_positions": [], "posed_joints": [], "foot_contacts": []}
        length = max(n for n, _ in samples)
        for n, constraint in samples:
            xz = constraint.smooth_root_2d.cpu().numpy().astype(np.float64)[:n]
            cos_sin = constraint.global_root_heading.cpu().numpy().astype(np.float64)[:n]
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
