"""Anatomical bodies from Anny, a parametric human body model, fitted to SONG's skeleton.

`Anny <https://github.com/naver/anny>`_ (NAVER, Apache-2.0 code; its mesh, blend shapes and rig are
MakeHuman assets from MPFB2 under CC0 1.0) turns six phenotype values — sex, age, muscle, weight, height,
proportions — into a 13,718-vertex body with a face (eyes, lips, nose, ears), hands with fingers and
feet, rigged to a 104-bone MakeHuman skeleton with up to 9 weights per vertex.

How a body reaches SONG (:func:`anny_body`):

1. **Phenotype** from the identity's anthropometry (:func:`phenotype`): sex, age in years (children's
   from their stature on the CDC curve, adults' drawn), height, weight and muscle from the identity's
   z-scores against the ANSUR II tables.
2. **Weights**: Anny's bone weights are summed onto SONG's 24 SMPL-topology joints (:data:`BONE_TO_JOINT`;
   a MakeHuman bone is driven by the joint at its head, as ours are), then cut to the top 4. This way
   round — the rig's weights to our skeleton, not our motion to its rig — because every motion source
   (Kimodo, the procedural gait, the compact motion caches and the LBS kernels) speaks the 24-joint
   skeleton, and Anny's artist-painted weights are better than a weight transfer by bone distance at
   the shoulders, hips and neck.
3. **Pose and proportions**: the mesh, scaled to the identity's stature, is moved from Anny's A-pose
   onto the T-pose skeleton :func:`song.geometry.skeleton.rest_joints` by linear blend skinning with one
   transform per joint that takes its bone in Anny's rest onto the same bone of ours (a rotation and a
   stretch along the bone), so the motion caches drive it exactly as they drive every other avatar.
4. Interior surfaces (mouth cavity, tongue, the back of the eyeballs and their sockets) are dropped.

Anny is optional (``pip install song[avatars]``; it needs torch and NVIDIA warp): :func:`available`
says whether it can be used, and the pool records which body each identity has.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from song.geometry.skeleton import JOINT_INDEX as J
from song.geometry.skeleton import JOINT_NAMES, N_JOINTS, rest_joints

ANNY_VERSION = "0.6.2"
# MakeHuman bone (by its name without the side) → the SONG joint that drives it
_CENTRE = {
    "root": "pelvis",
    "spine05": "pelvis",
    "spine04": "spine1",
    "spine03": "spine2",
    "spine02": "spine3",
    "spine01": "spine3",
    "neck01": "neck",
    "neck02": "neck",
    "neck03": "neck",
    "head": "head",
}
_SIDED = {
    "pelvis": "pelvis",
    "upperleg01": "{s}_hip",
    "upperleg02": "{s}_hip",
    "lowerleg01": "{s}_knee",
    "lowerleg02": "{s}_knee",
    "foot": "{s}_ankle",
    "toe": "{s}_foot",
    "clavicle": "{s}_collar",
    "shoulder01": "{s}_collar",
    "upperarm01": "{s}_shoulder",
    "upperarm02": "{s}_shoulder",
    "lowerarm01": "{s}_elbow",
    "lowerarm02": "{s}_elbow",
    "wrist": "{s}_wrist",
    "metacarpal": "{s}_wrist",
    "finger": "{s}_hand",
    "eye": "head",
}
# where each SONG joint sits on Anny's rig: the head of this bone ({s}: L or R)
_JOINT_BONE = {
    "pelvis": "root",
    "left_hip": "upperleg01.L",
    "right_hip": "upperleg01.R",
    "spine1": "spine04",
    "spine2": "spine03",
    "spine3": "spine02",
    "left_knee": "lowerleg01.L",
    "right_knee": "lowerleg01.R",
    "left_ankle": "foot.L",
    "right_ankle": "foot.R",
    "left_foot": "toe3-1.L",
    "right_foot": "toe3-1.R",
    "neck": "neck01",
    "left_collar": "clavicle.L",
    "right_collar": "clavicle.R",
    "head": "head",
    "left_shoulder": "upperarm01.L",
    "right_shoulder": "upperarm01.R",
    "left_elbow": "lowerarm01.L",
    "right_elbow": "lowerarm01.R",
    "left_wrist": "wrist.L",
    "right_wrist": "wrist.R",
    "left_hand": "finger3-1.L",
    "right_hand": "finger3-1.R",
}
# joints whose bone (to the child named here) is turned and stretched onto ours; the rest keep their
# orientation (the torso, neck and head stand upright in both rests) and only move
_LIMBS = {
    "left_hip": "left_knee",
    "right_hip": "right_knee",
    "left_knee": "left_ankle",
    "right_knee": "right_ankle",
    "left_ankle": "left_foot",
    "right_ankle": "right_foot",
    "left_shoulder": "left_elbow",
    "right_shoulder": "right_elbow",
    "left_elbow": "left_wrist",
    "right_elbow": "right_wrist",
    "left_wrist": "left_hand",
    "right_wrist": "right_hand",
}
_FOLLOW = {
    "left_hand": "left_wrist",
    "right_hand": "right_wrist",
    "left_foot": "left_ankle",
    "right_foot": "right_ankle",
}
INTERIOR = ("mouth_cavity", "tongue", "eye_back.L", "eye_back.R", "eye_cavity.L", "eye_cavity.R")
# Anny's frame (x left, −y forward, z up) → SONG's body frame (x forward, y left, z up)
_TO_SONG = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
# Anny's age anchors (newborn, baby, child, young, old) are MakeHuman's 0, 1, 11, 25 and 90 years
_AGE_YEARS = np.array([0.0, 1.0, 11.0, 25.0, 90.0])
_AGE_VALUES = np.array([-1.0 / 3.0, 0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0])


@functools.cache
def available() -> bool:
    """Whether Anny and what it needs (torch, NVIDIA warp) are installed.

    Asked of the import system without importing them (torch alone takes ~2 s to import, and every
    worker asks where its avatar pool lives); a broken install fails loudly when a pool is built.
    """
    from importlib.util import find_spec

    return all(find_spec(name) is not None for name in ("anny", "torch", "warp", "roma"))


def _joint_of_bone(label: str) -> str:
    name, _, side = label.partition(".")
    if name in _CENTRE:
        return _CENTRE[name]
    stem = name.split("-")[0].rstrip("0123456789") if name.startswith(("toe", "finger", "metacarpal")) else name
    joint = _SIDED[stem]
    return joint.format(s="left" if side == "L" else "right")


@dataclass(frozen=True)
class _Model:
    """What is read once from Anny: the model, its kept faces and regions, weights on our joints."""

    model: object
    faces: np.ndarray  # (F, 3) kept (exterior) triangles
    face_region: np.ndarray  # (F,) str: head, hand, foot, body, eye
    weights: np.ndarray  # (V, 24) Anny's weights summed onto our joints
    joint_bones: np.ndarray  # (24,) index of the bone whose head is each joint
    eye_bones: tuple[int, int]
    mouth: np.ndarray  # vertices of the mouth cavity (where the lips meet)


@functools.cache
def _load() -> _Model:
    import warp

    warp.config.log_level = warp.LOG_ERROR  # Anny initialises warp, which would print its devices to stdout
    import anny
    from anny.face_segmentation import get_face_segmentation_mask

    model = anny.Anny()
    labels = list(model.bone_labels)
    owner = np.array([J[_joint_of_bone(label)] for label in labels])
    index = model.vertex_bone_indices.numpy()
    weight = model.vertex_bone_weights.numpy()
    dense = np.zeros((len(index), N_JOINTS))
    np.add.at(dense, (np.repeat(np.arange(len(index)), index.shape[1]), owner[index].ravel()), weight.ravel())
    interior = get_face_segmentation_mask(model, list(INTERIOR))
    faces = model.faces.numpy()
    region = np.full(len(faces), "body", dtype=object)
    for label, name in (
        ("head", "head"),
        ("hand.L", "hand"),
        ("hand.R", "hand"),
        ("foot.L", "foot"),
        ("foot.R", "foot"),
    ):
        region[get_face_segmentation_mask(model, [label]).numpy()] = name
    region[get_face_segmentation_mask(model, ["eye_front.L", "eye_front.R"]).numpy()] = "eye"
    keep = ~interior.numpy()
    mouth = np.unique(faces[get_face_segmentation_mask(model, ["mouth_cavity"]).numpy()])
    return _Model(
        model=model,
        faces=faces[keep],
        face_region=region[keep].astype(str),
        weights=dense,
        joint_bones=np.array([labels.index(_JOINT_BONE[name]) for name in JOINT_NAMES]),
        eye_bones=(labels.index("eye.L"), labels.index("eye.R")),
        mouth=mouth,
    )


def phenotype(sex: str, age_years: float, z: dict[str, float]) -> dict[str, float]:
    """Anny's phenotype values for an identity (``z``: z-scores of stature, weight and muscle proxies)."""

    def unit(score: float) -> float:
        return float(np.clip(0.5 + 0.15 * score, 0.0, 1.0))

    return {
        "gender": 0.0 if sex == "male" else 1.0,
        "age": float(np.interp(age_years, _AGE_YEARS, _AGE_VALUES)),
        "muscle": unit(z.get("muscle", 0.0)),
        "weight": unit(z.get("weight", 0.0)),
        "height": unit(z.get("height", 0.0)),
        "proportions": 0.5,
    }


@dataclass
class BodyMesh:
    """An identity's body on SONG's rest skeleton (T-pose, x forward, y left, z up, soles at z ≈ 0).

    Attributes:
        vertices: (V, 3) metres.
        normals: (V, 3) unit vertex normals.
        faces: (F, 3) exterior triangles.
        face_region: (F,) ``head``, ``eye``, ``hand``, ``foot`` or ``body``.
        weights: (V, 24) skinning weights on SONG's joints (rows sum to 1).
        joints: (24, 3) the rest skeleton the body is fitted to.
        eyes: (2, 3) eyeball centres, left then right.
        mouth: (3,) the middle of the lips' meeting line.
    """

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    face_region: np.ndarray
    weights: np.ndarray
    joints: np.ndarray
    eyes: np.ndarray
    mouth: np.ndarray


def _rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``a`` to direction ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def _fit_transforms(source: np.ndarray, target: np.ndarray, lift: float = 0.0) -> np.ndarray:
    """(24, 3, 4) affine maps: each joint's bone in ``source`` onto the same bone in ``target``.

    ``lift`` raises the head (and the neck by half) above where its joint takes it: Anny's skull sits
    higher over its head joint than our skeleton's proportions place it, and the body keeps its stature.
    """
    out = np.zeros((N_JOINTS, 3, 4))
    linear = {}
    for joint in range(N_JOINTS):
        name = JOINT_NAMES[joint]
        m = np.eye(3)
        if name in _LIMBS:
            child = J[_LIMBS[name]]
            a, b = source[child] - source[joint], target[child] - target[joint]
            rot = _rotation(a, b)
            axis = b / np.linalg.norm(b)
            stretch = np.linalg.norm(b) / np.linalg.norm(a)
            m = (np.eye(3) + (stretch - 1.0) * np.outer(axis, axis)) @ rot
        linear[name] = m
    for name, parent in _FOLLOW.items():
        linear[name] = linear[parent]
    for joint, name in enumerate(JOINT_NAMES):
        out[joint, :, :3] = linear[name]
        out[joint, :, 3] = target[joint] - linear[name] @ source[joint]
    out[J["head"], 2, 3] += lift
    out[J["neck"], 2, 3] += 0.5 * lift
    return out


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = vertices[faces]
    face_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # area-weighted
    normals = np.zeros_like(vertices)
    for corner in range(3):
        np.add.at(normals, faces[:, corner], face_normal)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)


def anny_body(stature_m: float, values: dict[str, float]) -> BodyMesh:
    """Anny's body for these phenotype ``values``, scaled to ``stature_m`` and fitted to SONG's rest skeleton."""
    import torch

    data = _load()
    model = data.model
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # one identity is a few small matrix products: threads only add noise
    try:
        phenotypes = {k: torch.tensor([v], dtype=torch.float64) for k, v in values.items()}
        with torch.no_grad():
            inputs = model.get_tensor_inputs(None, phenotypes, None, None)
            rest = model.get_rest_model(model._get_phenotype_blendshape_coefficients(*inputs[1:]))
    finally:
        torch.set_num_threads(threads)
    vertices = rest["rest_vertices"][0].numpy() @ _TO_SONG.T
    heads = rest["rest_bone_heads"][0].numpy() @ _TO_SONG.T
    used = np.unique(data.faces)
    floor, top = vertices[used, 2].min(), vertices[used, 2].max()
    scale = stature_m / (top - floor)
    origin = np.array([0.0, 0.0, floor])
    vertices, heads = (vertices - origin) * scale, (heads - origin) * scale
    source = heads[data.joint_bones]
    target = rest_joints(stature_m)
    weights = data.weights

    def fit(lift: float) -> tuple[np.ndarray, np.ndarray]:
        maps = _fit_transforms(source, target, lift)
        moved = np.einsum("vj,jab,vb->va", weights, maps[:, :, :3], vertices) + weights @ maps[:, :, 3]
        return moved, maps[J["head"]]

    moved, head_map = fit(0.0)
    moved, head_map = fit(stature_m - moved[used, 2].max())  # the crown back at the stature
    eyes = np.stack([heads[b] for b in data.eye_bones]) @ head_map[:, :3].T + head_map[:, 3]
    mouth = moved[data.mouth]
    mouth = mouth[mouth[:, 0] > mouth[:, 0].max() - 0.005].mean(axis=0)
    return BodyMesh(
        vertices=np.round(moved, 6),
        normals=_vertex_normals(moved, data.faces),
        faces=data.faces,
        face_region=data.face_region,
        weights=weights,
        joints=target,
        eyes=eyes,
        mouth=mouth,
    )
