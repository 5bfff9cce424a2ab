"""A plain capsule-body avatar for tests (independent of the procedural generator).

Gaussians are spread on cylinders around the skeleton's bones (radius per bone from a small table),
weighted by :func:`song.datasets.avatars.skinning.transfer_weights`.
"""

from __future__ import annotations

import numpy as np

from song.datasets.avatars.asset import AvatarAsset
from song.datasets.avatars.skinning import bone_segments, transfer_weights
from song.datasets.scenes.ply import GaussianCloud
from song.geometry.rotations import quat_normalize
from song.geometry.skeleton import rest_joints


def capsule_avatar(avatar_id: str = "capsule", n: int = 3000, height: float = 1.75, seed: int = 0) -> AvatarAsset:
    rng = np.random.default_rng(seed)
    rest = rest_joints(height)
    start, end, _ = bone_segments(rest, height)
    length = np.linalg.norm(end - start, axis=1)
    bone = rng.choice(len(start), size=n, p=length / length.sum())
    t = rng.random(n)
    axis = end[bone] - start[bone]
    unit = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-9)
    helper = np.where(np.abs(unit[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(unit, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(unit, u)
    phi = rng.random(n) * 2 * np.pi
    radius = 0.04 * height / 1.75
    means = start[bone] + t[:, None] * axis + radius * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v)
    means[:, 2] = np.maximum(means[:, 2], 0.0)
    means[:, 2] -= means[:, 2].min()
    indices, weights = transfer_weights(means, rest, height)
    cloud = GaussianCloud(
        means=means.astype(np.float32),
        quats=quat_normalize(rng.normal(size=(n, 4))).astype(np.float32),
        log_scales=np.full((n, 3), np.log(0.01), np.float32),
        opacity_logits=np.full(n, 3.0, np.float32),
        sh_dc=rng.normal(0, 0.5, (n, 3)).astype(np.float32),
    )
    meta = {"source": "test-capsule", "height_m": float(height), "generator": {"seed": seed}}
    return AvatarAsset(avatar_id, cloud, indices, weights, rest.astype(np.float32), meta)
