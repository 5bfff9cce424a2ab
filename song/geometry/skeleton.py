"""The 24-joint SMPL topology with our own procedural rest proportions.

Joint names and parent indices of SMPL are public facts. The rest offsets are NOT taken from any
licensed SMPL model file: they are our own proportions of a standing human, as fractions of body
height, in the body frame used everywhere in SONG: **x forward, y left, z up**, feet on z = 0,
T-pose (arms along ±y). Heading θ of a body is the yaw of its +x axis.
"""

from __future__ import annotations

import numpy as np

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
)
PARENTS: np.ndarray = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21], dtype=np.int64
)
N_JOINTS = len(JOINT_NAMES)
JOINT_INDEX = {name: index for index, name in enumerate(JOINT_NAMES)}

# Rest joint positions for a 1 m tall body (x forward, y left, z up). Our own proportions, chosen
# from anthropometric ratios (hip ≈ 0.49 H, knee ≈ 0.285 H, ankle ≈ 0.045 H, shoulder ≈ 0.815 H,
# arm span ≈ H); left joints have y > 0.
_REST_UNIT = np.array(
    [
        [0.000, 0.000, 0.530],  # pelvis
        [0.000, 0.055, 0.485],  # left_hip
        [0.000, -0.055, 0.485],  # right_hip
        [-0.010, 0.000, 0.590],  # spine1
        [0.005, 0.055, 0.285],  # left_knee
        [0.005, -0.055, 0.285],  # right_knee
        [-0.010, 0.000, 0.655],  # spine2
        [-0.010, 0.055, 0.045],  # left_ankle
        [-0.010, -0.055, 0.045],  # right_ankle
        [-0.005, 0.000, 0.720],  # spine3
        [0.075, 0.060, 0.012],  # left_foot (ball of the foot)
        [0.075, -0.060, 0.012],  # right_foot
        [0.000, 0.000, 0.830],  # neck
        [0.000, 0.040, 0.800],  # left_collar
        [0.000, -0.040, 0.800],  # right_collar
        [0.010, 0.000, 0.875],  # head
        [0.000, 0.105, 0.815],  # left_shoulder
        [0.000, -0.105, 0.815],  # right_shoulder
        [0.000, 0.270, 0.815],  # left_elbow
        [0.000, -0.270, 0.815],  # right_elbow
        [0.000, 0.410, 0.815],  # left_wrist
        [0.000, -0.410, 0.815],  # right_wrist
        [0.000, 0.465, 0.815],  # left_hand
        [0.000, -0.465, 0.815],  # right_hand
    ],
    dtype=np.float64,
)


def rest_joints(height_m: float | np.ndarray = 1.75) -> np.ndarray:
    """World rest joint positions of a standing body of the given height(s).

    Args:
        height_m: scalar or (B,) body heights, metres (typically 1.50–1.95).

    Returns:
        (24, 3) or (B, 24, 3) float64, metres; feet on z ≈ 0, pelvis above the origin.
    """
    height = np.asarray(height_m, dtype=np.float64)
    return _REST_UNIT * height[..., None, None]
