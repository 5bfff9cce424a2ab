"""Procedural gait: a footstep-planned, IK-driven walk that follows a planned root track exactly.

How it works:

1. **Cadence and phase.** The step frequency follows the walk-ratio model ``f = √(v/WR)`` steps/s
   (step length ``L = √(v·WR)``, so ``f·L = v``), floored at ``min_cadence_spm``. A gait phase ``s``
   (one unit per step, two per stride) is integrated from ``f`` so it stays continuous through speed
   changes. The left foot swings for ``s mod 2 ∈ [0, 0.8)`` and the right for ``[1, 1.8)``: each foot
   is in stance 60 % of a stride and swings 40 %, with two double-support windows per stride.
2. **Stopping, idling, turning on the spot.** The phase only rests in the middle of a double
   support. While the pedestrian moves, turns faster than ``_TURN_RATE`` or has a foot away from its
   neutral stance (translation or yaw), the phase advances; otherwise it freezes and the body idles
   (breathing, slow weight shift, looking around) with both feet planted.
3. **Footsteps.** When a foot lifts, its next stance is placed under the hip at the predicted
   mid-stance time (read from the *planned* trajectory, so deceleration and stops are anticipated),
   with the style's step width and toe-out. Stance feet never move (zero skating by construction);
   they roll over the heel after touchdown and over the ball before lift-off.
4. **Swing.** The foot leaves the floor heel-high and travels forward at once (a minimum-jerk profile
   over the whole swing); its height peaks early in the swing and falls while it reaches forward; it
   pitches from toe-down to toe-up. Short steps are shuffles, lifted in proportion to their travel.
5. **Body.** The pelvis follows the plan with a small lateral sway and a vertical bob, lowered where
   needed so both ankles stay reachable; pelvic rotation and list, counter-rotating thorax, lean
   into turns (``atan(v·ω/g)``), counter-phase arm swing with forward-only elbow flexion, a
   stabilised head. Legs are solved with two-bone IK (knee pole = foot forward), so knees never
   hyper-extend.

Per-pedestrian style (height, walk ratio, arm swing, posture, step width, toe-out, phase) is drawn
from the pedestrian's seed, so a crowd does not walk in lockstep.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from song.config import MotionConfig
from song.geometry.fk import global_to_local
from song.geometry.ik import two_bone_ik
from song.geometry.rotations import matrix_to_quat, quat_slerp, quat_to_matrix, rot_x, rot_y, rot_z, wrap_angle
from song.geometry.skeleton import JOINT_INDEX as J
from song.geometry.skeleton import PARENTS, rest_joints
from song.pipeline.motion.postures import (
    EDGE_CLEAR_M,
    INTO_SHELF_M,
    LIFT_CLEAR_M,
    ONTO_SURFACE_M,
    PALM_M,
    REACH_FLEX_DEG,
    SHOULDER_FLEX_DEG,
    arm_on_surface,
    arm_to,
    browse_plan,
)
from song.pipeline.motion.types import (
    Motion,
    Trajectory,
    body_heading,
    held_rows,
    min_jerk,
    path_yaw,
    rate_limited,
    true_runs,
)

# Walk ratio (step length / step frequency) is constant per person across speeds, 0.34-0.42 m·s in adults
# around 0.38, and grows with body height (Sekiya & Nagasaki 1998, Gait Posture 7:225): the configured walk
# ratio is that of a person of the mean height, scaled by height and by ±7 % per person. A short person
# taking a tall person's steps walks with an over-extended hip.
MEAN_HEIGHT_M, HEIGHT_SD_M = 1.71, 0.09
WALK_RATIO_SPREAD = (0.93, 1.07)
# The pelvis is lowered exactly as far as the leg reaches need where they bind, and elsewhere no faster
# than PELVIS_DROP_STEP_M per frame at 30 FPS (a Gaussian-smoothed cap reached over from the neighbouring
# frames, so the knee was bent 12-17° at heel strike at 1.4 m/s; slower limits hold the pelvis low for
# longer around each double support: 0.02 m gave a 57° hip range at 1.4 m/s instead of 49°); then by a
# loading-response dip: the knee yields 15-20° after heel strike (peak at 12-15 % of the cycle) and
# straightens by mid-stance (Perry & Burnfield 2010); at the skeleton's shank and thigh that is ~1 cm.
PELVIS_DROP_STEP_M = 0.04  # m per frame (1.2 m/s)
LOADING_DIP_M = 0.01
LOADING_WINDOW = (0.8, 1.1, 1.5)  # foot phase: heel strike, deepest, straight again (stance is 0.8-2.0)
LEG_REACH = 0.999  # the pelvis is lowered so that no ankle target lies beyond this share of the leg
SWING = 0.8  # swing length in step units (40 % of a 2-step stride)
REST_PHASE = 0.9  # the phase rests in the middle of a double support (s mod 1 = 0.9)
_MOVE_SPEED = 0.08  # m/s: below this the plan is "standing"
_TURN_RATE = 0.35  # rad/s: above this a standing pedestrian steps round (turning on the spot)
_SETTLE_POS = 0.06  # m: a planted foot farther than this from its neutral spot triggers a step
_SETTLE_YAW = 0.3  # rad: same for foot yaw
_GRAVITY = 9.81
# The foot lands under the hip 0.55 steps after touchdown (~46 % into its 1.2-step stance), not at
# mid-stance: heel-off at the end of stance lifts the ankle, so the leg reaches farther behind than ahead.
_PLACE_AT = 0.55
# Foot pitch at lift-off: the heel is raised ~60° as the toe leaves the floor (foot-floor angle at toe-off
# ~55-65° in walking at 1.2-1.6 m/s: Winter 1991, foot segment angle). A high heel lifts and advances the
# trailing ankle, so the leg reaches behind with the knee bent instead of the hip over-extended.
_TOE_OFF_DEG = 60.0
# The heel rises over the last quarter of stance (terminal stance, ~45-60 % of the cycle: Perry & Burnfield
# 2010); rising earlier bends the trailing knee while the pelvis is low at the opposite heel strike.
HEEL_RISE_FROM = 0.75
_HEEL_STRIKE_DEG = 10.0  # foot pitch at touchdown (toes up)
# Swing (fractions of the swing). The ankle's height rises fast after toe-off (peak knee flexion in initial
# swing, ~60° at 70-75 % of the cycle) and then comes down over the rest of the swing while the foot reaches
# forward, so the knee extends on the way to heel strike instead of the thigh lifting a high foot far ahead
# (hip flexion ~30-35° at terminal swing; Perry & Burnfield 2010; ankle height falls through mid- and
# terminal swing: Winter 1992, Phys. Ther. 72:45). Lift = clip(a + b·stride, a, max) metres at 1.75 m height.
# The lift bump rises over the first 20 % and falls over the last 65 % when walking; short steps while
# standing or turning on the spot keep it up to 70 % (they travel late and low, and the toe must clear).
SWING_LIFT_RISE, SWING_LIFT_FALL = 0.2, (0.65, 0.3)  # rise; fall (walking, standing)
SWING_DESCENT = 0.6  # the ankle goes from its toe-off height to its heel-strike height over the first 60 %
SWING_LIFT = (0.06, 0.05, 0.10)  # a, b, max
# Short steps (starting, stopping, repositioning, turning on the spot) are shuffles: the lift shrinks with
# the toe's travel (the ankle's, plus the toe's sweep as the foot turns) below SHUFFLE_TRAVEL_M, down to
# SHUFFLE_LIFT_M. A foot that travels this little never moves fast enough near the floor to read as
# sliding (its peak speed at 85 steps/min is ~3.3 × travel/s).
SHUFFLE_TRAVEL_M, SHUFFLE_LIFT_M = 0.3, 0.01
SWING_PITCH = (0.05, 0.6)  # the foot turns from toe-down (toe-off) to toe-up (heel strike) over this window
# Shoulder swing amplitude a + b·v degrees (scaled per person by 0.75-1.25): ±10-25° at 1.0-1.4 m/s, growing
# with speed (Murray et al. 1967, J. Bone Joint Surg. 49A:336; Collins et al. 2009, Proc. R. Soc. B 276:3679).
ARM_SWING_DEG = (6.0, 10.0)
SPINE_PITCH_SHARE = (("spine1", 1 / 3), ("spine2", 2 / 3))  # of the chest's rotation, the rest is spine3's
_CHAIN = {  # the joints from the pelvis to each shoulder, in order
    side: [J["spine1"], J["spine2"], J["spine3"], J[f"{side}_collar"], J[f"{side}_shoulder"]]
    for side in ("left", "right")
}
ARM_HANG_DEG = 82.0  # the arms hang this far down from the T-pose (8° out from the body)
TOUCH_BLEND_S = 0.3  # touching a shelf item, the solved arm takes over from the hanging one within no less than this
ARM_STRAIGHT = 0.975  # a solved arm reaches at most this share of its length (arm_to declines past 0.98)
HANDS_ITERATIONS = 2  # corrections of the hands' planar solve by where the arm really puts them
HANDS_INWARD_DEG = 15.0  # resting on a surface, the fingers point this far inward of straight ahead
HANDS_RAMP_S = 1.0  # the arms move onto a counter, desk or table, and off it, over about this long
HANDS_LEAN_DEG = np.arange(5.0, 46.0, 5.0)  # resting the hands there, the trunk leans the least of these
HANDS_HEAD_DEG = 12.0  # that reaches; at a surface the head looks down this much (and half the lean farther)
# Of that lean the hips take this share (the pelvis tilts forward) and the spine the rest: in forward
# bending the lumbar spine and the hips contribute about equally over the first 40-60° (the lumbopelvic
# rhythm; Esola et al. 1996, Spine 21:71). Bending at the hips lowers the shoulders more than the same
# lean of the spine alone: every adult height then reaches a 0.9 m counter from the crowd's standing
# spots (0.4-0.5 m away), where a spine-only lean of up to 20° reached it only up to 1.6 m, 0.4 m away.
HANDS_HIP_SHARE = 0.5
CHEST_GAZE_SHARE = 0.2  # browsing a shelf, the chest turns this share of the way the head looks
# and the head turns toward the point looked at within these (the eyes do the rest; head rotation on
# the trunk reaches ~70° and neck flexion ~50°, so these leave room)
GAZE_YAW_DEG, GAZE_PITCH_DEG = (-45.0, 45.0), (-25.0, 40.0)  # left +, down +
HANDS_SLACK_M = 0.03  # a surface counts as reachable from a lean when it would be from this much farther
# Anticipatory steering: in walking turns the head turns first, ~0.2-0.25 s before the path, then the
# trunk and the pelvis (Grasso et al. 1998, NeuroReport 9:1169; Patla et al. 1999, Exp. Brain Res. 129:629).
HEAD_LEAD_S, TRUNK_LEAD_S, PELVIS_LEAD_S = 0.25, 0.2, 0.15


@dataclass(frozen=True)
class GaitStyle:
    """Per-pedestrian style, drawn from its seed (see :func:`sample_style`)."""

    height_m: float
    walk_ratio: float  # m·s
    arm_swing: float  # scale of the arm-swing amplitude
    elbow_flex_deg: float
    lean_deg: float  # forward trunk lean
    step_width: float  # fraction of the hip width between the feet centres
    toe_out_deg: float
    sway_m: float  # pelvis lateral sway amplitude at full walk
    bob_m: float  # pelvis vertical bob amplitude at full walk
    head_pitch_deg: float
    start_phase: float  # 0.9 (left foot leads) or 1.9 (right foot leads)
    idle_phase: float  # radians, offsets the idle weight shift

    def to_json(self) -> dict:
        """The style as a JSON-able dict (recorded in each motion's meta)."""
        return {k: round(v, 6) for k, v in asdict(self).items()}


def sample_style(
    rng: np.random.Generator, height_range: tuple[float, float] = (1.5, 1.95), walk_ratio: float = 0.38
) -> GaitStyle:
    """Draw a style. Heights: normal(1.71 m, 0.09 m) clipped to ``height_range``; WR ∝ height, ±7 %."""
    lo, hi = height_range
    height = float(np.clip(rng.normal(MEAN_HEIGHT_M, HEIGHT_SD_M), lo, hi))
    return GaitStyle(
        height_m=height,
        walk_ratio=float(walk_ratio * height / MEAN_HEIGHT_M * rng.uniform(*WALK_RATIO_SPREAD)),
        arm_swing=float(rng.uniform(0.75, 1.25)),
        elbow_flex_deg=float(rng.uniform(8.0, 20.0)),
        lean_deg=float(rng.uniform(1.0, 5.0)),
        step_width=float(rng.uniform(0.75, 1.05)),
        toe_out_deg=float(rng.uniform(3.0, 11.0)),
        sway_m=float(rng.uniform(0.008, 0.014)),
        bob_m=float(rng.uniform(0.012, 0.022)),
        head_pitch_deg=float(rng.uniform(-4.0, 6.0)),
        start_phase=float(REST_PHASE + rng.integers(0, 2)),
        idle_phase=float(rng.uniform(0.0, 2 * np.pi)),
    )


def style_for(seed: int, cfg: MotionConfig) -> GaitStyle:
    """The per-pedestrian style (and body height) drawn from its seed (every generator uses it)."""
    return sample_style(np.random.default_rng(seed), (cfg.height_min_m, cfg.height_max_m), cfg.walk_ratio_m_s)


def cadence_steps_per_s(speed: np.ndarray, walk_ratio: float, min_cadence_spm: float) -> np.ndarray:
    """Walk-ratio cadence ``max(√(v/WR), f_min)`` in steps/s for speeds ``(...)`` m/s."""
    return np.maximum(np.sqrt(np.maximum(speed, 0.0) / walk_ratio), min_cadence_spm / 60.0)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass
class _Plan:
    """Smoothed plan signals at the trajectory's frames."""

    t: np.ndarray
    xy: np.ndarray
    heading: np.ndarray  # unwrapped, smoothed
    speed: np.ndarray
    yaw_rate: np.ndarray
    walk: np.ndarray  # 0 standing … 1 walking (smooth)

    def pose_at(self, time: float) -> tuple[float, float, float]:
        x = float(np.interp(time, self.t, self.xy[:, 0]))
        y = float(np.interp(time, self.t, self.xy[:, 1]))
        return x, y, float(np.interp(time, self.t, self.heading))


def _ahead(signal: np.ndarray, t: np.ndarray, lead_s: float) -> np.ndarray:
    """``signal`` read ``lead_s`` seconds later (held at the end): a segment that turns before the path."""
    return np.interp(t + lead_s, t, signal)


def _plan_signals(traj: Trajectory) -> _Plan:
    t = traj.t
    dt = 1.0 / traj.fps
    heading = gaussian_filter1d(body_heading(path_yaw(traj), t), 2.0, mode="nearest")
    if len(t) > 1:
        vel = np.gradient(traj.xy, t, axis=0)
        speed = gaussian_filter1d(np.linalg.norm(vel, axis=1), 2.0, mode="nearest")
        yaw_rate = gaussian_filter1d(np.gradient(heading, t), 2.0, mode="nearest")
    else:
        speed = np.zeros(1)
        yaw_rate = np.zeros(1)
    walk = gaussian_filter1d(np.clip(speed / 0.6, 0.0, 1.0), 0.25 / dt, mode="nearest")
    return _Plan(t=t, xy=traj.xy, heading=heading, speed=speed, yaw_rate=yaw_rate, walk=walk)


def _integrate_phase(
    plan: _Plan, style: GaitStyle, half_width: float, min_cadence_spm: float
) -> tuple[np.ndarray, dict[int, dict[int, tuple[float, float, float]]]]:
    """Phase per frame and the stance placements ``{foot: {index: (x, y, yaw)}}`` (0 left, 1 right).

    A plain loop over frames with Python floats (a few operations per frame): the only sequential
    part of the generator.
    """
    t, n = plan.t, len(plan.t)
    side = (1.0, -1.0)
    toe_out = math.radians(style.toe_out_deg)
    cadence = cadence_steps_per_s(plan.speed, style.walk_ratio, min_cadence_spm).tolist()
    moving = ((plan.speed > _MOVE_SPEED) | (np.abs(plan.yaw_rate) > _TURN_RATE)).tolist()
    xs, ys, hs, ts = plan.xy[:, 0].tolist(), plan.xy[:, 1].tolist(), plan.heading.tolist(), t.tolist()

    def neutral(foot: int, x: float, y: float, h: float) -> tuple[float, float, float]:
        s = side[foot]
        return (x - s * half_width * math.sin(h), y + s * half_width * math.cos(h), h + s * toe_out)

    def off(foot: int, i: int) -> bool:
        px, py, ph = stance[foot][last[foot]]
        nx, ny, nh = neutral(foot, xs[i], ys[i], hs[i])
        dyaw = wrap_angle(ph - nh)
        return math.hypot(px - nx, py - ny) > _SETTLE_POS or abs(dyaw) > _SETTLE_YAW

    s = style.start_phase
    last = [math.floor(s / 2.0), math.floor((s - 1.0) / 2.0)]
    stance = {f: {last[f]: neutral(f, xs[0], ys[0], hs[0])} for f in (0, 1)}
    phase = np.empty(n)
    frozen = True
    for i in range(n):
        phase[i] = s
        if i == n - 1:
            break
        if frozen:
            if not (moving[i] or off(0, i) or off(1, i)):
                continue
            frozen = False
        rate = cadence[i]
        dt = ts[i + 1] - ts[i]
        s_new = s + rate * dt
        k = math.floor(s) + 1  # next integer phase: a lift-off
        while k <= s_new:
            foot = k % 2
            lift_time = ts[i] + (k - s) / rate
            x, y, h = plan.pose_at(lift_time + (SWING + _PLACE_AT) / rate)
            index = (k - foot) // 2
            stance[foot][index] = neutral(foot, x, y, h)
            last[foot] = index
            k += 1
        rest = math.floor(s - REST_PHASE) + 1 + REST_PHASE  # next resting point
        if rest <= s_new and not (moving[i + 1] or off(0, i + 1) or off(1, i + 1)):
            s_new, frozen = rest, True
        s = s_new
    return phase, stance


def _stance_arrays(stance: dict[int, tuple[float, float, float]]) -> tuple[int, np.ndarray]:
    lo, hi = min(stance), max(stance)
    out = np.empty((hi - lo + 1, 3))
    previous = stance[lo]
    for j in range(lo, hi + 1):
        previous = stance.get(j, previous)
        out[j - lo] = previous
    return lo, out


class _Body:
    """Rest-skeleton quantities of one body height."""

    def __init__(self, height: float) -> None:
        self.height = height
        self.rest = rest_joints(height)
        r = self.rest
        self.ankle_off = r[J["left_ankle"]] - r[J["left_foot"]]  # ankle from ball of foot (left)
        self.heel = np.array([r[J["left_ankle"], 0] - 0.03 * height, 0.0, 0.0])  # heel point x, on floor
        self.ankle_h = float(r[J["left_ankle"], 2])
        self.half_width = float(r[J["left_hip"], 1])
        # the hip-ankle distance of the rest pose: the skeleton's knee is slightly bent at rest, so a leg
        # stretched farther than this would bend the knee backwards (knee flexion is measured from rest)
        self.leg = float(np.linalg.norm(r[J["left_ankle"]] - r[J["left_hip"]]))
        self.upper_arm = float(np.linalg.norm(r[J["left_elbow"]] - r[J["left_shoulder"]]))
        self.forearm = float(np.linalg.norm(r[J["left_wrist"]] - r[J["left_elbow"]]))
        # a hand lying flat, fingers turned in by HANDS_INWARD_DEG: its mid-palm joint this far ahead of the wrist
        self.hand_length = float(np.linalg.norm(r[J["left_hand"]] - r[J["left_wrist"]]))  # wrist to mid-palm
        self.hand_reach = self.hand_length * float(np.cos(np.radians(HANDS_INWARD_DEG)))

    def hands_on_surface(self, traj: Trajectory, idle: np.ndarray, lean: float) -> tuple[np.ndarray, np.ndarray]:
        """How much (0-1) the body rests its hands on a counter, desk or table, and how far it leans (rad).

        Per frame of ``traj.surface``: the least forward lean among ``HANDS_LEAN_DEG`` (on top of the
        body's own ``lean``, which the spine takes; of the extra lean the hips take ``HANDS_HIP_SHARE``,
        tilting the pelvis, and the spine the rest, as the gait pitches it) from which the standing
        body reaches the surface (:func:`song.pipeline.motion.postures.arm_on_surface`); both ramped
        on and off over ``HANDS_RAMP_S``.
        """
        n = traj.n_frames
        if traj.surface is None:
            return np.zeros(n), np.zeros(n)
        edge, height = traj.surface.T
        at = np.flatnonzero(np.isfinite(edge))
        need = np.full(n, np.nan)
        spine = {J["pelvis"]: 0.0, **{J[name]: w for name, w in SPINE_PITCH_SHARE}}
        extras = np.radians(HANDS_LEAN_DEG)
        shoulder = np.tile(self.rest[0, [0, 2]], (len(extras), 1))  # (x forward, z up) per lean
        for joint in _CHAIN["left"]:  # each offset turns (about y) with its parent's share of the chest's pitch
            parent = PARENTS[joint]
            share = spine.get(parent, 1.0)  # of the lean the hips do not take
            pitch = share * lean + (HANDS_HIP_SHARE + (1.0 - HANDS_HIP_SHARE) * share) * extras
            dx, dz = (self.rest[joint] - self.rest[parent])[[0, 2]]
            shoulder += np.stack([dx * np.cos(pitch) + dz * np.sin(pitch), dz * np.cos(pitch) - dx * np.sin(pitch)], -1)
        # with some slack: the pose's own sway and breathing must not take the surface out of reach
        far = edge[at] - self.hand_reach + HANDS_SLACK_M
        for extra, point in zip(extras[::-1], shoulder[::-1], strict=True):  # the least lean that reaches wins
            reach = arm_on_surface(far, height[at], point, self.upper_arm, self.forearm, lean + extra)[2]
            need[at[reach]] = extra
        sigma = HANDS_RAMP_S / 4.0 * traj.fps
        hold = gaussian_filter1d(np.isfinite(need).astype(np.float64), sigma, mode="nearest") * idle
        return hold, gaussian_filter1d(np.nan_to_num(held_rows(need[:, None])[:, 0], nan=0.0), sigma, mode="nearest")


def _arm(rot_chest: np.ndarray, swing: np.ndarray, flex: np.ndarray, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Global shoulder and elbow rotations ``(T, 3, 3)``: the arm hangs ``ARM_HANG_DEG``, swung and bent forward."""
    shoulder = rot_chest @ rot_y(-swing) @ rot_x(np.full(len(swing), sign * np.radians(ARM_HANG_DEG)))
    return shoulder, shoulder @ rot_z(sign * flex)


class _PlanarArm:
    """One arm solved in the body's sagittal plane from where its shoulder is in a pose, over ``frames``.

    ``glob`` holds the pelvis, spine and collar rotations (the trunk's lean included); the arm swings
    in the chest's frame, which leans forward by ``chest_pitch`` (rad), so the planar solve's shoulder
    flexion (from the vertical) is that swing less the lean. Each solve is a planar two-bone solve
    (:func:`song.pipeline.motion.postures.arm_to`) corrected ``HANDS_ITERATIONS`` times by where the
    arm, hanging slightly out to the side, really puts the wrist. Every array it takes or returns
    covers ``frames`` only (the frames where the arm does something: a few seconds of a minute).
    """

    def __init__(
        self, xy: np.ndarray, body: _Body, glob: np.ndarray, pelvis: np.ndarray, heading: np.ndarray,
        side: str, sign: float, chest_pitch: np.ndarray, frames: slice,
    ) -> None:  # fmt: skip
        rest = body.rest
        glob = glob[frames]
        shoulder = pelvis[frames].copy()
        for joint in _CHAIN[side]:  # the shoulder's ancestors, pelvis first
            parent = PARENTS[joint]
            shoulder += np.einsum("tij,j->ti", glob[:, parent], rest[joint] - rest[parent])
        self.xy, self.body, self.sign, self.chest_pitch = xy[frames], body, sign, chest_pitch[frames]
        self.shoulder, self.chest = shoulder, glob[:, J["spine3"]]
        self.forward = np.stack([np.cos(heading[frames]), np.sin(heading[frames])], axis=-1)
        self.upper = rest[J[f"{side}_elbow"]] - rest[J[f"{side}_shoulder"]]
        self.fore = rest[J[f"{side}_wrist"]] - rest[J[f"{side}_elbow"]]
        self.local = np.stack([((shoulder[:, :2] - self.xy) * self.forward).sum(-1), shoulder[:, 2]], axis=-1)
        self.bones = (self.local, body.upper_arm, body.forearm)  # arm_to's shoulder and lengths

    def wrist_at(self, flex_s: np.ndarray, flex_e: np.ndarray) -> np.ndarray:
        """``(F, 2)`` the wrist's [distance ahead of the plan, height] for planar shoulder and elbow flexions."""
        rot_s, rot_e = _arm(self.chest, flex_s + self.chest_pitch, flex_e, self.sign)
        hand = self.shoulder + np.einsum("tij,j->ti", rot_s, self.upper) + np.einsum("tij,j->ti", rot_e, self.fore)
        return np.stack([((hand[:, :2] - self.xy) * self.forward).sum(-1), hand[:, 2]], axis=-1)

    def solve(self, target: np.ndarray, flex_deg: tuple = SHOULDER_FLEX_DEG) -> tuple[np.ndarray, ...]:
        """Shoulder flexion, elbow flexion (rad) and where possible, putting the wrist at ``target`` ``(F, 2)``.

        A target a little out of reach (by at most ``HANDS_SLACK_M``: the pose's sway and breathing) is
        pulled in to where the arm reaches, so the hand stays there instead of dropping for a frame.
        """
        reach = ARM_STRAIGHT * (self.body.upper_arm + self.body.forearm)
        offset = target - self.local
        distance = np.linalg.norm(offset, axis=1, keepdims=True)
        near = distance <= reach / ARM_STRAIGHT + HANDS_SLACK_M
        target = np.where(near & (distance > reach), self.local + offset * (reach / np.maximum(distance, 1e-9)), target)
        aim = target.copy()
        for _ in range(HANDS_ITERATIONS):
            flex_s, flex_e, possible = arm_to(*aim.T, *self.bones, flex_deg, self.chest_pitch)
            aim = aim - np.where(possible[:, None], self.wrist_at(flex_s, flex_e) - target, 0.0)
        return arm_to(*aim.T, *self.bones, flex_deg, self.chest_pitch)


def _active(weight: np.ndarray, pad: int) -> list[slice]:
    """The runs of frames where ``weight`` > 0, each widened by ``pad`` frames on both sides (merged)."""
    near = np.convolve(weight > 0.0, np.ones(2 * pad + 1), mode="same") > 0.0
    return [slice(a, b) for a, b in true_runs(near)]


def _blend_in(
    flex_s: np.ndarray, flex_e: np.ndarray, possible: np.ndarray, weight: np.ndarray, steps: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How much (0-1) a solved arm takes over from the hanging one, and its angles.

    The weight follows ``weight`` where the solve is possible and 0 elsewhere, changing over at least
    ``steps`` frames from 0 to 1 (0: at once), in time order: it rises only once a pose is possible,
    and where a target goes out of reach the arm keeps its last reachable pose while the weight falls.
    """
    w = np.where(possible, weight, 0.0)
    if steps > 1.0:
        level = 0.0
        for i, value in enumerate(w.tolist()):  # a touch: a couple of seconds of frames
            level = min(max(value, level - 1.0 / steps), level + 1.0 / steps)
            w[i] = level
    angles = np.nan_to_num(held_rows(np.where(possible[:, None], np.stack([flex_s, flex_e], -1), np.nan)))
    return w, angles[:, 0], angles[:, 1]


def _hands_on(
    arm: _PlanarArm, surface: np.ndarray, hold: np.ndarray, base_flex: float, fps: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shoulder flexion, elbow flexion (rad) and palm turn (0-1) of one arm going onto ``surface`` by ``hold``.

    The hand follows a path in the sagittal plane as ``hold`` goes 0 → 1: from where it hangs, up and
    forward until it clears the top by ``LIFT_CLEAR_M`` even pointing down, the whole hand
    ``EDGE_CLEAR_M`` short of the edge, then forward onto the surface (leaving, back the same way), so
    it never passes through the edge; every frame is a :meth:`_PlanarArm.solve`, blended in by
    :func:`_blend_in`. The palm turns from facing the thigh to lying flat as the hand moves over the
    surface. Where the surface is out of reach the arm hangs as it would.
    """
    body, chest_pitch = arm.body, arm.chest_pitch
    end = held_rows(surface) + np.array([ONTO_SURFACE_M - body.hand_reach, PALM_M])  # the wrist of a flat hand
    ramp = np.minimum(hold, gaussian_filter1d(arm.solve(end)[2].astype(np.float64), HANDS_RAMP_S / 4.0 * fps))
    ramp = rate_limited(ramp, 1.0 / (HANDS_RAMP_S * fps))  # the last turning step ends at once
    hanging = arm.wrist_at(-chest_pitch, np.full(len(hold), base_flex))
    lift = np.stack([np.maximum(hanging[:, 0], end[:, 0] - ONTO_SURFACE_M - EDGE_CLEAR_M),
                     end[:, 1] - PALM_M + body.hand_length + LIFT_CLEAR_M], axis=-1)  # fmt: skip
    up, over = _smoothstep(np.clip(2.0 * ramp, 0.0, 1.0)), _smoothstep(np.clip(2.0 * ramp - 1.0, 0.0, 1.0))
    path = np.where(
        (ramp < 0.5)[:, None], hanging + up[:, None] * (lift - hanging), lift + over[:, None] * (end - lift)
    )
    flex_s, flex_e, possible = arm.solve(path)
    # the arm leaves its hanging angles near the start of the path, where the solved pose is close to them
    w, flex_s, flex_e = _blend_in(flex_s, flex_e, possible, _smoothstep(np.clip(5.0 * ramp, 0.0, 1.0)), 0.0)
    return w * (flex_s + chest_pitch), (1.0 - w) * base_flex + w * flex_e, np.where(possible, over, 0.0)


def _touch_shelf(
    arm: _PlanarArm, front: np.ndarray, height: np.ndarray, reach: np.ndarray, base_flex: float, fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Shoulder and elbow flexion (rad) of one arm touching an item on a shelf by ``reach``.

    The wrist's target lies a hand's length short of ``INTO_SHELF_M`` past the shelf's ``front`` (m
    ahead), at ``height`` (the point looked at); the arm's angles go there from the hanging arm's in
    proportion to ``reach`` (minimum-jerk in :func:`song.pipeline.motion.postures.browse_plan`; blended
    by :func:`_blend_in`), so the hand comes up and forward without passing through the shelf. Out of
    reach, the arm hangs.
    """
    target = np.stack([front + INTO_SHELF_M - arm.body.hand_reach, height], axis=-1)
    flex_s, flex_e, possible = arm.solve(target, REACH_FLEX_DEG)
    w, flex_s, flex_e = _blend_in(flex_s, flex_e, possible, reach, TOUCH_BLEND_S * fps)
    return w * (flex_s + arm.chest_pitch), (1.0 - w) * base_flex + w * flex_e


def _foot_poses(
    body: _Body, phase_foot: np.ndarray, walk: np.ndarray, lo: int, placements: np.ndarray, side: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ankle targets ``(T, 3)``, foot yaw ``(T,)``, pitch ``(T,)`` and stance flags ``(T,)`` of one foot."""
    j = np.floor(phase_foot / 2.0).astype(np.int64)
    u = phase_foot - 2.0 * j
    in_swing = u < SWING
    cur = placements[np.clip(j - lo, 0, len(placements) - 1)]
    prev = placements[np.clip(j - 1 - lo, 0, len(placements) - 1)]
    h_scale = body.height / 1.75
    beta_off, beta_on = np.radians(_TOE_OFF_DEG) * walk, np.radians(_HEEL_STRIKE_DEG) * walk

    def pose(anchor_xy: np.ndarray, yaw: np.ndarray, pitch: np.ndarray, pivot: str) -> np.ndarray:
        # ankle position for a foot planted at anchor (flat-foot ankle xy), rotated by pitch about a pivot
        cos, sin = np.cos(yaw), np.sin(yaw)
        if pivot == "toe":
            off_flat = -body.ankle_off  # toe from ankle, flat
            piv_local = np.array([off_flat[0], 0.0, off_flat[2]])
        else:
            piv_local = np.array([body.heel[0] - body.rest[J["left_ankle"], 0], 0.0, -body.ankle_h])
        arm = -piv_local  # pivot → ankle, in the foot frame before pitch
        cp, sp = np.cos(pitch), np.sin(pitch)
        ax = arm[0] * cp + arm[2] * sp
        az = -arm[0] * sp + arm[2] * cp
        px = anchor_xy[:, 0] + piv_local[0] * cos
        py = anchor_xy[:, 1] + piv_local[0] * sin
        return np.stack([px + ax * cos, py + ax * sin, body.ankle_h + piv_local[2] + az], axis=-1)

    tau = np.clip((u - SWING) / (2.0 - SWING), 0.0, 1.0)
    stance_pitch = beta_off * _smoothstep((tau - HEEL_RISE_FROM) / (1.0 - HEEL_RISE_FROM)) - beta_on * (
        1.0 - _smoothstep(tau / 0.15)
    )
    heel_phase = tau < 0.3
    stance_pos = np.where(
        heel_phase[:, None],
        pose(cur[:, :2], cur[:, 2], np.minimum(stance_pitch, 0.0), "heel"),
        pose(cur[:, :2], cur[:, 2], np.maximum(stance_pitch, 0.0), "toe"),
    )
    sigma = np.clip(u / SWING, 0.0, 1.0)
    start = pose(prev[:, :2], prev[:, 2], beta_off, "toe")
    end = pose(cur[:, :2], cur[:, 2], -beta_on, "heel")
    # forward travel: minimum jerk over the whole swing from toe-off (it used to wait 6 % of the swing, so the
    # foot trailed the body and the hip over-extended); cut before its end (the foot still moving at
    # touchdown) it took 5° more off the hip range at 1.4 m/s but bent the knee at heel strike and the toe
    # skimmed the floor (benchmarks/motion.py --normative)
    progress = min_jerk(sigma)
    distance = np.linalg.norm(end[:, :2] - start[:, :2], axis=1)
    lift = np.clip(SWING_LIFT[0] + SWING_LIFT[1] * distance, SWING_LIFT[0], SWING_LIFT[2]) * h_scale
    toe_travel = distance + np.linalg.norm(body.ankle_off[:2]) * np.abs(wrap_angle(cur[:, 2] - prev[:, 2]))
    lift = np.maximum(lift * _smoothstep(toe_travel / SHUFFLE_TRAVEL_M), SHUFFLE_LIFT_M * h_scale)
    fall = SWING_LIFT_FALL[1] + (SWING_LIFT_FALL[0] - SWING_LIFT_FALL[1]) * walk
    bump = _smoothstep(sigma / SWING_LIFT_RISE) * _smoothstep((1.0 - sigma) / fall)
    swing_pos = start + (end - start) * progress[:, None]
    swing_pos[:, 2] = start[:, 2] + (end[:, 2] - start[:, 2]) * _smoothstep(sigma / SWING_DESCENT) + lift * bump
    swing_yaw = prev[:, 2] + wrap_angle(cur[:, 2] - prev[:, 2]) * progress
    turn = _smoothstep((sigma - SWING_PITCH[0]) / (SWING_PITCH[1] - SWING_PITCH[0]))
    swing_pitch = beta_off + (-beta_on - beta_off) * turn
    ankle = np.where(in_swing[:, None], swing_pos, stance_pos)
    yaw = np.where(in_swing, swing_yaw, cur[:, 2])
    pitch = np.where(in_swing, swing_pitch, stance_pitch)
    del side
    return ankle, yaw, pitch, ~in_swing


def _within(v: np.ndarray, length: float) -> np.ndarray:
    """Vectors ``(T, 3)`` shortened to at most ``length``."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v * np.minimum(1.0, length / np.maximum(norm, 1e-12))


def _slerp_matrix(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    return quat_to_matrix(quat_slerp(matrix_to_quat(a), matrix_to_quat(b), w))


def _lowered_pelvis(
    z_nominal: np.ndarray, hips: list[np.ndarray], ankles: list[np.ndarray], pelvis_z: np.ndarray, reach: np.ndarray
) -> np.ndarray:
    """Pelvis heights ≤ nominal that keep both ankle targets within ``reach`` of their hips, slope-limited.

    Equal to the cap where it binds; elsewhere the highest curve below it that moves at most
    ``PELVIS_DROP_STEP_M`` per frame (so the pelvis starts down early enough instead of dropping in
    one frame).
    """
    cap = z_nominal.copy()
    for hip, ankle in zip(hips, ankles, strict=True):
        horizontal = np.linalg.norm(ankle[:, :2] - hip[:, :2], axis=1)
        vertical = np.sqrt(np.maximum(reach * reach - horizontal * horizontal, (0.5 * reach) ** 2))
        cap = np.minimum(cap, ankle[:, 2] + vertical - (hip[:, 2] - pelvis_z))
    if len(cap) > 1:
        # the highest curve under the cap whose height changes by at most PELVIS_DROP_STEP_M per frame: a
        # cone erosion, min_j (cap_j + step·|i − j|), as two running minima
        ramp = np.arange(len(cap)) * PELVIS_DROP_STEP_M
        ahead = ramp + np.minimum.accumulate(cap - ramp)
        behind = np.minimum.accumulate((cap + ramp)[::-1])[::-1] - ramp
        cap = np.minimum(ahead, behind)
    return cap


def _loading_dip(phase_foot: np.ndarray) -> np.ndarray:
    """Pelvis lowering (m, at 1.75 m height) while one foot takes the body's weight after heel strike."""
    u = np.mod(phase_foot, 2.0)
    a, peak, b = LOADING_WINDOW
    rise = _smoothstep((u - a) / (peak - a))
    fall = _smoothstep((b - u) / (b - peak))
    return LOADING_DIP_M * np.where(u < peak, rise, fall) * ((u >= a) & (u <= b))


@dataclass
class _Walk:
    """What every part of one pedestrian's gait reads: the plan, the phase and the pose built so far."""

    traj: Trajectory
    style: GaitStyle
    body: _Body
    plan: _Plan
    phase: np.ndarray
    glob: np.ndarray  # (T, 24, 3, 3) global joint rotations, filled part by part
    on_surface: np.ndarray  # (T,) how far the hands rest on a surface, 0..1
    surface_lean: np.ndarray  # (T,) the lean that takes them there, rad

    @property
    def n(self) -> int:
        return self.traj.n_frames

    @property
    def walk(self) -> np.ndarray:
        return self.plan.walk

    @property
    def idle(self) -> np.ndarray:
        return 1.0 - self.plan.walk

    @property
    def lean(self) -> float:
        return float(np.radians(self.style.lean_deg))

    @property
    def breathing(self) -> np.ndarray:
        return np.sin(2 * np.pi * 0.25 * self.traj.t + self.style.idle_phase)


def _feet(w: _Walk, stance) -> tuple[list, list, list, list]:
    """Per foot: ankle positions, foot rotations, planted flags and knee poles."""
    ankles, foot_rots, contacts, poles = [], [], [], []
    for foot, side in ((0, 1.0), (1, -1.0)):
        lo, placements = _stance_arrays(stance[foot])
        ankle, yaw, pitch, planted = _foot_poses(w.body, w.phase - foot, w.walk, lo, placements, side)
        ankles.append(ankle)
        foot_rots.append(rot_z(yaw) @ rot_y(pitch))
        contacts.append(planted)
        poles.append(np.stack([np.cos(yaw), np.sin(yaw), np.zeros(w.n)], axis=-1))
    return ankles, foot_rots, contacts, poles


def _pelvis(w: _Walk, ankles: list) -> tuple[np.ndarray, np.ndarray, list, np.ndarray, np.ndarray]:
    """Pelvis: sway, bob, rotation, list; lean into turns; lowered so the legs reach the feet.

    Returns ``(pelvis (T, 3), its rotation (T, 3, 3), the hips, its yaw oscillation, the turn roll)``.
    """
    plan, phase, walk, idle, style, t = w.plan, w.phase, w.walk, w.idle, w.style, w.traj.t
    rest = w.body.rest
    h_scale = style.height_m / 1.75
    left = np.stack([-np.sin(plan.heading), np.cos(plan.heading)], axis=-1)
    sway = walk * style.sway_m * np.cos(np.pi * (phase - 1.4)) + idle * 0.008 * np.sin(
        2 * np.pi * 0.1 * t + style.idle_phase
    )
    yaw_osc = -walk * np.radians(4.0) * np.cos(np.pi * (phase - 0.8))
    pelvic_list = walk * np.radians(3.0) * np.cos(np.pi * (phase - 1.4))
    turn_roll = -np.clip(0.8 * np.arctan(plan.speed * plan.yaw_rate / _GRAVITY), -0.17, 0.17)
    pelvis_heading = _ahead(plan.heading, t, PELVIS_LEAD_S)
    on_surface, surface_lean = w.on_surface, w.surface_lean
    tilt = 0.3 * w.lean * walk + HANDS_HIP_SHARE * on_surface * surface_lean
    rot_pelvis = rot_z(pelvis_heading + yaw_osc) @ rot_x(pelvic_list + 0.3 * turn_roll) @ rot_y(tilt)
    pelvis = np.empty((w.n, 3))
    pelvis[:, :2] = w.traj.xy + sway[:, None] * left
    z_nominal = rest[0, 2] + walk * style.bob_m * np.cos(2 * np.pi * (phase - 1.4))
    z_nominal = z_nominal + idle * 0.002 * w.breathing
    hip_offsets = [rot_pelvis @ (rest[J[name]] - rest[0]) for name in ("left_hip", "right_hip")]
    pelvis[:, 2] = z_nominal
    hips = [pelvis + off for off in hip_offsets]
    pelvis[:, 2] = _lowered_pelvis(z_nominal, hips, ankles, z_nominal, w.body.leg * LEG_REACH)
    pelvis[:, 2] -= walk * h_scale * (_loading_dip(phase) + _loading_dip(phase - 1.0))
    hips = [pelvis + off for off in hip_offsets]
    w.glob[:, 0] = rot_pelvis
    return pelvis, rot_pelvis, hips, yaw_osc, turn_roll


def _legs(w: _Walk, rot_pelvis: np.ndarray, hips: list, ankles: list, foot_rots: list, poles: list) -> None:
    """Thighs and shins by two-bone IK from the hips to the ankles (never stretched past the rest pose)."""
    rest = w.body.rest
    pelvis_fwd = rot_pelvis[:, :, 0]
    names = (
        ("left_hip", "left_knee", "left_ankle", "left_foot"),
        ("right_hip", "right_knee", "right_ankle", "right_foot"),
    )
    for (hip_name, knee_name, ankle_name, foot_name), hip, ankle, rot_foot, pole in zip(
        names, hips, ankles, foot_rots, poles, strict=True
    ):
        knee_rest = hip + rest[J[knee_name]] - rest[J[hip_name]]
        ankle_rest = hip + rest[J[ankle_name]] - rest[J[hip_name]]
        bend_pole = pole + pelvis_fwd
        reach = hip + _within(ankle - hip, w.body.leg * LEG_REACH)
        ankle = np.where((np.linalg.norm(ankle - hip, axis=1) > w.body.leg * LEG_REACH)[:, None], reach, ankle)
        _, _, thigh, shin = two_bone_ik(hip, knee_rest, ankle_rest, ankle, bend_pole, np.array([1.0, 0.0, 0.0]))
        w.glob[:, J[hip_name]] = thigh
        w.glob[:, J[knee_name]] = shin
        w.glob[:, J[ankle_name]] = rot_foot
        w.glob[:, J[foot_name]] = rot_foot


def _trunk_and_head(w: _Walk, rot_pelvis: np.ndarray, yaw_osc: np.ndarray, turn_roll: np.ndarray):
    """Spine, chest, neck and head: lean, turns led by the gaze, looking at a shelf or down at a surface.

    Returns ``(chest rotation, chest pitch, the shelf browse plan or None)``.
    """
    traj, idle, heading, t = w.traj, w.idle, w.plan.heading, w.traj.t
    rest = w.body.rest
    on_surface, surface_lean = w.on_surface, w.surface_lean
    chest_pitch = w.lean * (0.5 + 0.5 * w.walk) + idle * np.radians(1.0) * w.breathing
    chest_pitch = chest_pitch + on_surface * surface_lean
    browse = None if traj.shelf is None else browse_plan(traj.shelf, traj.fps, traj.ped_id)
    browsing, gaze_yaw, gaze_pitch = np.zeros(w.n), np.zeros(w.n), np.zeros(w.n)
    if browse is not None:  # the head turns to the point looked at on the shelf, the chest a little
        front = held_rows(traj.shelf)[:, 0]
        browsing = browse.on * idle
        gaze_yaw = np.clip(np.arctan2(browse.look[:, 0], front), *np.radians(GAZE_YAW_DEG))
        gaze_pitch = np.clip(np.arctan2(rest[J["head"], 2] - browse.look[:, 1], front), *np.radians(GAZE_PITCH_DEG))
    chest_yaw = _ahead(heading, t, TRUNK_LEAD_S) - 0.5 * yaw_osc + CHEST_GAZE_SHARE * browsing * gaze_yaw
    rot_chest = rot_z(chest_yaw) @ rot_x(turn_roll) @ rot_y(chest_pitch)
    for name, share in SPINE_PITCH_SHARE:
        w.glob[:, J[name]] = _slerp_matrix(rot_pelvis, rot_chest, share)
    w.glob[:, J["spine3"]] = rot_chest
    wander = idle * 0.25 * np.sin(2 * np.pi * 0.07 * t + w.style.idle_phase)  # looking around
    look = _ahead(heading, t, HEAD_LEAD_S) + (1.0 - browsing) * wander + browsing * gaze_yaw
    head_pitch = np.radians(w.style.head_pitch_deg) + on_surface * 0.5 * surface_lean
    if traj.surface is not None:  # at a surface, within reach or not, the head looks down at it
        at = np.isfinite(traj.surface[:, 0]).astype(np.float64)
        at = gaussian_filter1d(at, HANDS_RAMP_S / 4.0 * traj.fps, mode="nearest")
        head_pitch = head_pitch + at * idle * np.radians(HANDS_HEAD_DEG)
    head_pitch = head_pitch + browsing * gaze_pitch
    rot_head = rot_z(look) @ rot_x(0.3 * turn_roll) @ rot_y(head_pitch)
    w.glob[:, J["head"]] = rot_head
    w.glob[:, J["neck"]] = _slerp_matrix(rot_chest, rot_head, 0.5)
    w.glob[:, J["left_collar"]] = rot_chest
    w.glob[:, J["right_collar"]] = rot_chest
    return rot_chest, chest_pitch, browse


def _arms(w: _Walk, pelvis: np.ndarray, rot_chest: np.ndarray, chest_pitch: np.ndarray, browse) -> None:
    """Arm swing while walking; hands laid on a surface or reaching to a shelf while standing."""
    traj, style, heading, idle, n = w.traj, w.style, w.plan.heading, w.idle, w.n
    on_surface = w.on_surface
    amplitude = np.radians(style.arm_swing * (ARM_SWING_DEG[0] + ARM_SWING_DEG[1] * np.clip(w.plan.speed, 0.0, 1.5)))
    swing_left = w.walk * amplitude * np.cos(np.pi * (w.phase - 1.8))
    for prefix, sign, swing in (("left", -1.0, swing_left), ("right", 1.0, -swing_left)):
        on_shoulder, flex, palm = np.zeros(n), np.full(n, np.radians(style.elbow_flex_deg)), np.zeros(n)
        # the ramps and their smoothing reach 2 × HANDS_RAMP_S beyond where the hands hold: nothing moves outside
        for f in _active(on_surface, int(2 * HANDS_RAMP_S * traj.fps)):
            arm = _PlanarArm(traj.xy, w.body, w.glob, pelvis, heading, prefix, sign, chest_pitch, f)
            on_shoulder[f], flex[f], palm[f] = _hands_on(arm, traj.surface[f], on_surface[f], flex[0], traj.fps)
        touch = np.zeros(n) if browse is None else browse.reach * idle * (browse.left == (prefix == "left"))
        for f in _active(touch, 0):
            arm = _PlanarArm(traj.xy, w.body, w.glob, pelvis, heading, prefix, sign, chest_pitch, f)
            on_shoulder[f], flex[f] = _touch_shelf(
                arm, traj.shelf[f, 0], browse.look[f, 1], touch[f], flex[0], traj.fps
            )
        flex = flex + 0.5 * np.maximum(swing, 0.0)
        shoulder, elbow = _arm(rot_chest, swing + on_shoulder, flex, sign)
        # resting, the hand lies flat on the surface, fingers forward and a little inward (the T-pose's palms face down)
        hand = elbow
        if palm.any():
            flat = rot_z(heading + sign * np.radians(90.0 + HANDS_INWARD_DEG))
            hand = quat_to_matrix(quat_slerp(matrix_to_quat(elbow), matrix_to_quat(flat), palm))
        if touch.any():  # touching an item on a shelf, the fingers point forward, the palm faces in
            grip = rot_z(heading + sign * np.radians(90.0)) @ rot_y(np.full(n, -np.pi / 2))
            hand = quat_to_matrix(quat_slerp(matrix_to_quat(hand), matrix_to_quat(grip), touch))
        w.glob[:, J[f"{prefix}_shoulder"]] = shoulder
        w.glob[:, J[f"{prefix}_elbow"]] = elbow
        w.glob[:, J[f"{prefix}_wrist"]] = hand
        w.glob[:, J[f"{prefix}_hand"]] = hand


def generate_gait(traj: Trajectory, style: GaitStyle, min_cadence_spm: float = 85.0) -> Motion:
    """Procedural full-body walk that follows ``traj`` (see the module docstring).

    Feet first (footholds from the phase), then the pelvis over them, the legs by IK, the trunk and
    head, the arms.

    Args:
        traj: the planned root track (30 FPS, world frame).
        style: per-pedestrian style (height, walk ratio, ...).
        min_cadence_spm: cadence floor, steps/min.

    Returns:
        A :class:`Motion` at the trajectory's time stamps, with stance flags as ``contacts``.
    """
    body = _Body(style.height_m)
    plan = _plan_signals(traj)
    phase, stance = _integrate_phase(plan, style, body.half_width * style.step_width, min_cadence_spm)
    glob = np.broadcast_to(np.eye(3), (traj.n_frames, 24, 3, 3)).copy()
    on_surface, surface_lean = body.hands_on_surface(traj, 1.0 - plan.walk, 0.5 * np.radians(style.lean_deg))
    w = _Walk(traj, style, body, plan, phase, glob, on_surface, surface_lean)
    ankles, foot_rots, contacts, poles = _feet(w, stance)
    pelvis, rot_pelvis, hips, yaw_osc, turn_roll = _pelvis(w, ankles)
    _legs(w, rot_pelvis, hips, ankles, foot_rots, poles)
    rot_chest, chest_pitch, browse = _trunk_and_head(w, rot_pelvis, yaw_osc, turn_roll)
    _arms(w, pelvis, rot_chest, chest_pitch, browse)
    return Motion(
        ped_id=traj.ped_id,
        t=traj.t.copy(),
        frame=traj.frame.astype(np.int32),
        height_m=style.height_m,
        rest_joints=body.rest,
        local_quats=matrix_to_quat(global_to_local(w.glob)),
        root_pos=pelvis,
        contacts=np.stack(contacts, axis=-1),
        info={"style": style.to_json()},
    )
