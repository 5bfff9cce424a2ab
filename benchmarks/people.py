"""Do detectors trained on real photos believe our people? BlazePose, MediaPipe faces and segmentation, OpenCV.

    .venv/bin/python benchmarks/people.py [--bench runs/demo-bench] [--body 40] [--faces 16] [--out runs/bench-people]

Sets up its own environment for the judges (``mediapipe==0.10.21`` from PyPI, which brings OpenCV, in
``build/bench-envs/people``; never a dependency of ``song``) and runs them there on frames this script
renders with the runtime's own renderer and avatars (``song.runtime.vision.SceneView``: the release's
scene Gaussians, its pedestrians' avatars posed by their motion caches, lit by the scene's probes).

**Frames.** From the release's episodes, seeded: a pedestrian at a time of its track, and a camera placed
at distance d from it, at an angle φ from the way its body faces, looking at it; a frame is kept only
when the camera stands in free space and nothing of the scene hides more than 5 % of the person (the
other pedestrians are left out, so each frame shows one person). 960×540, 70° horizontal field of view.
- ``body``: d ∈ [2, 8] m, φ ∈ ±60°, the robot camera (0.8 m high, level).
- ``face``: d ∈ [1, 2.5] m, φ ∈ ±15°, a level camera at the height of the head joint (a frontal
  portrait, the view the face detectors are trained on; a 0.8 m camera sees a face at 1 m from 39° below).
- ``back``: as ``face`` but from behind (φ ∈ 180 ± 15°), half as many: the detectors' false alarms on the
  back of a head, the control that a "face found" means a face.

**Figures** (``score``; the detectors' raw outputs are in ``OUT/frames/detections.json``):
- BlazePose: share of ``body`` frames at d ≥ 2.7 m with a pose; of their 12 limb keypoints (shoulders,
  elbows, wrists, hips, knees, ankles) the share within 10 % of the person's box height of our
  skeleton's projected joint (the person's box: rows and columns of our alpha > 0.5).
  Targets ≥ 97 % and ≥ 80 %. Twice: on the whole frame (BlazePose's own person detector sees the
  frame at 224 px, where a person 6 m away is ~40 px tall and its face, which that detector keys on,
  ~5 px) and on the person crop (square, side 1.25 × the box height), as a person detector would hand
  it over.
- Faces: share of ``face`` frames where MediaPipe's short-range detector (run on a square crop of
  side 0.6 m at the person's distance, centred on the head joint: a head-and-shoulders portrait, as a
  person detector would hand it over) finds a face whose centre lies within 0.12 m (at the person's
  distance) of the face's centre, 0.06 m above the projected head joint (the joint sits at the base of
  the skull, level with the chin); d ∈ [1, 2]. Target ≥ 70 %. OpenCV's Haar cascade on the whole frame,
  d ∈ [1.5, 2.5]: target ≥ 50 %. The same shares on ``back`` frames are reported as false alarms.
- HOG: share of ``body`` frames with a detection matching the person: IoU ≥ 0.5 between the two boxes
  at the pedestrian-detection convention (Caltech's: each box's height, width 0.41 × height; a HOG box
  holds its person in the central 96 of its window's 128 rows). Target ≥ 95 %.
  Also on the frames where HOG's window can hold the person at all (box height × 128/96 ≤ the frame's
  height: a person nearer than ~3.5 m fills the frame's height and no window fits), and by distance
  (``hog_by_distance``: 2–3, 3–4, 4–6, 6–8 m).
- Face brightness (``face_luma_by_skin_tone``): on ``face`` frames, the median display luma (Rec. 709 weights
  on the sRGB values) of the mid-face patch (0.05 m square on the face's centre: nose and cheeks), by Monk band, against the luma of the avatar's skin swatch: how much
  darker the scene's light renders a face than its swatch.
- Segmentation: MediaPipe's person mask on a square crop (side 1.25 × the box height) against our
  alpha > 0.5, IoU inside the crop, ``body`` frames at d ∈ [2, 4]. Target ≥ 0.8 (median).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._common import ROOT, bench_env, emit  # noqa: E402
from song.geometry.skeleton import JOINT_INDEX  # noqa: E402

ENV = ROOT / "build" / "bench-envs" / "people"
MEDIAPIPE_VERSION = "0.10.21"
WIDTH, HEIGHT, HFOV = 960, 540, 70.0
ROBOT_CAMERA_M = 0.8
# MediaPipe pose landmark index → our joint (the person's own left and right in both).
LIMBS = {
    11: "left_shoulder",
    12: "right_shoulder",
    13: "left_elbow",
    14: "right_elbow",
    15: "left_wrist",
    16: "right_wrist",
    23: "left_hip",
    24: "right_hip",
    25: "left_knee",
    26: "right_knee",
    27: "left_ankle",
    28: "right_ankle",
}
FACE_TOLERANCE_M = 0.12
# the face's centre (nose and cheeks, between the brows and the chin): this far above the head joint, which sits
# at the base of the skull, level with the chin (0.875 of the height; the face centre is at ~0.91)
FACE_CENTRE_RISE_M = 0.06
HOG_WINDOW_RATIO = 128 / 96  # the HOG window's height over the person's height in its training crops
FACE_CROP_M = 0.6
FACE_PATCH_M = 0.05  # the side of the mid-face patch whose luma is measured, centred on the face's centre
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 luma weights, applied to sRGB-encoded values


def ensure_detectors() -> Path:
    """The Python of the benchmark's own MediaPipe environment (created on first use)."""
    return bench_env(ENV, "import mediapipe, cv2", [f"mediapipe=={MEDIAPIPE_VERSION}"])


def _box(mask: np.ndarray) -> list[int] | None:
    """``[x0, y0, x1, y1]`` (inclusive-exclusive) of a boolean mask, or None when empty."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not len(rows):
        return None
    return [int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1]


def _iou_boxes(a: list[float], b: list[float]) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def _standard(box: list[float]) -> list[float]:
    """A person's box at the pedestrian-detection convention: its height, width 0.41 × height, same centre."""
    cx, half = (box[0] + box[2]) / 2, 0.41 * (box[3] - box[1]) / 2
    return [cx - half, box[1], cx + half, box[3]]


def _hog_person(det: list[float]) -> list[float]:
    """The person inside a HOG detection (x, y, w, h, …): the central 96 of its window's 128 rows, standardised."""
    x, y, w, h = det[:4]
    return _standard([x, y + h / 8, x + w, y + 7 * h / 8])


def _face_centre(frame: dict) -> tuple[float, float]:
    """The face's centre in a ``face``/``back`` frame: the head joint raised by :data:`FACE_CENTRE_RISE_M` (level camera)."""
    hx, hy = frame["head_px"]
    return hx, hy - frame["focal_px"] * FACE_CENTRE_RISE_M / frame["distance_m"]


def _face_hit(boxes: list[list[float]], frame: dict) -> bool:
    """A detected face (x, y, w, h, …) centred within the tolerance of the face's centre (:func:`_face_centre`)."""
    hx, hy = _face_centre(frame)
    tolerance = frame["focal_px"] * FACE_TOLERANCE_M / frame["distance_m"]
    return any(math.hypot(b[0] + b[2] / 2 - hx, b[1] + b[3] / 2 - hy) <= tolerance for b in boxes)


def face_luma(rgb: np.ndarray, mask: np.ndarray, frame: dict) -> float | None:
    """Median display luma (0–1) of the mid-face patch of a ``face`` frame (level camera), inside our mask."""
    half = max(1, round(frame["focal_px"] * FACE_PATCH_M / frame["distance_m"] / 2))
    cx, cy = (round(c) for c in _face_centre(frame))
    window = (slice(max(cy - half, 0), cy + half), slice(max(cx - half, 0), cx + half))
    inside = mask[window]
    if inside.sum() < 4:
        return None
    return float(np.median(rgb[window][inside].astype(np.float64) @ LUMA / 255.0))


def swatch_luma(mst: float) -> float:
    """Display luma of the skin colour the pool gives at a place on the Monk scale (the colour as the avatar's albedo)."""
    from song.datasets.avatars.generate import skin_colour

    return float(skin_colour(mst) @ LUMA)


HOG_BANDS = {"2-3 m": (2.0, 3.0), "3-4 m": (3.0, 4.0), "4-6 m": (4.0, 6.0), "6-8 m": (6.0, 8.0)}  # body frames

TONE_BANDS = {"MST 1-4": (1.0, 4.0), "MST 4-7": (4.0, 7.0), "MST 7-10": (7.0, 10.0)}  # Monk Skin Tone places


def _band(x: float, bands: dict[str, tuple[float, float]]) -> str:
    """The first band whose upper end lies above ``x``; the last band holds its own upper end."""
    return next((name for name, (_, hi) in bands.items() if x < hi), list(bands)[-1])


def _tone_band(mst: float | None) -> str | None:
    """The band of a place on the Monk Skin Tone scale (None for an avatar without one)."""
    return _band(mst, TONE_BANDS) if mst else None


def _share(hits: list[bool]) -> dict:
    return {"n": len(hits), "hits": int(sum(hits)), "share": round(float(np.mean(hits)), 3) if hits else None}


def score(
    frames: list[dict],
    detections: list[dict],
    masks: list[np.ndarray],
    segmented: list[np.ndarray],
    lumas: list[float | None] | None = None,
) -> dict:
    """The figures from the frames' ground truth and the detectors' raw outputs (see the module docstring).

    Args:
        frames: per frame ``kind``, ``distance_m``, ``focal_px``, ``box`` (the person's), ``joints_px``
            (our joint name → [x, y]), ``head_px``, ``person_crop`` ``[x0, y0, side]``.
        detections: per frame ``pose`` (33 × [x, y, visibility] or None), ``face_short`` and ``haar``
            (lists of [x, y, w, h, …]), ``hog`` (lists of [x, y, w, h, weight]).
        masks: our person mask per frame (alpha > 0.5, unoccluded). segmented: MediaPipe's mask per frame.
        lumas: :func:`face_luma` per frame (None where not measured).
    """
    pose = {"frame": ([], [], []), "crop": ([], [], [])}  # found, keypoints within 10 %, errors
    hog, hog_fits, seg = [], [], []
    hog_by_band: dict[str, list[bool]] = {name: [] for name in HOG_BANDS}
    face_mp, face_haar, back_mp, back_haar = [], [], [], []
    by_tone = {"mediapipe": {name: [] for name in TONE_BANDS}, "haar": {name: [] for name in TONE_BANDS}}
    luma_by_tone: dict[str, list[tuple[float, float]]] = {name: [] for name in TONE_BANDS}
    lumas = lumas if lumas is not None else [None] * len(frames)
    for frame, det, ours, theirs, luma in zip(frames, detections, masks, segmented, lumas, strict=True):
        d = frame["distance_m"]
        if frame["kind"] in ("face", "back"):
            mp_list, haar_list = (face_mp, face_haar) if frame["kind"] == "face" else (back_mp, back_haar)
            band = _tone_band(frame.get("skin_mst")) if frame["kind"] == "face" else None
            if band and luma is not None:
                luma_by_tone[band].append((luma, swatch_luma(frame["skin_mst"])))
            if d <= 2.0:
                mp_list.append(_face_hit(det["face_short"], frame))
                if band:
                    by_tone["mediapipe"][band].append(mp_list[-1])
            if d >= 1.5:
                haar_list.append(_face_hit(det["haar"], frame))
                if band:
                    by_tone["haar"][band].append(haar_list[-1])
            continue
        box = frame["box"]
        box_h = box[3] - box[1]
        found = any(_iou_boxes(_standard(box), _hog_person(b)) >= 0.5 for b in det["hog"])
        hog.append(found)
        hog_by_band[_band(d, HOG_BANDS)].append(found)
        if box_h * HOG_WINDOW_RATIO <= HEIGHT:
            hog_fits.append(found)
        if d >= 2.7:
            for where, key in (("frame", "pose"), ("crop", "pose_crop")):
                found_list, keypoints, errors = pose[where]
                landmarks = det.get(key)
                found_list.append(landmarks is not None)
                for index, joint in LIMBS.items() if landmarks is not None else ():
                    x, y = landmarks[index][:2]
                    jx, jy = frame["joints_px"][joint]
                    errors.append(math.hypot(x - jx, y - jy) / box_h)
                    keypoints.append(errors[-1] <= 0.1)
        if d <= 4.0:
            x0, y0, side = frame["person_crop"]
            window = (slice(max(y0, 0), y0 + side), slice(max(x0, 0), x0 + side))
            a, b = ours[window], theirs[window]
            union = np.logical_or(a, b).sum()
            seg.append(float(np.logical_and(a, b).sum() / union) if union else 0.0)
    record = {}
    for where, (found_list, keypoints, errors) in pose.items():
        record[f"blazepose_{where}"] = {
            "found": _share(found_list),
            "keypoints_within_10pct": _share(keypoints),
            "median_keypoint_error_box_heights": round(float(np.median(errors)), 4) if errors else None,
        }
    return {
        **record,
        "face_mediapipe_short_1_2m": _share(face_mp),
        "face_haar_1p5_2p5m": _share(face_haar),
        "face_from_behind_mediapipe_1_2m": _share(back_mp),
        "face_from_behind_haar_1p5_2p5m": _share(back_haar),
        "faces_by_skin_tone": {
            judge: {band: _share(hits) for band, hits in bands.items() if hits} for judge, bands in by_tone.items()
        },
        "face_luma_by_skin_tone": {
            band: {
                "n": len(pairs),
                "face_median": round(float(np.median([a for a, _ in pairs])), 3),
                "swatch_median": round(float(np.median([b for _, b in pairs])), 3),
                "face_over_swatch_median": round(float(np.median([a / b for a, b in pairs])), 3),
            }
            for band, pairs in luma_by_tone.items()
            if pairs
        },
        "hog_2_8m": _share(hog),
        "hog_2_8m_window_fits": _share(hog_fits),
        "hog_by_distance": {band: _share(hits) for band, hits in hog_by_band.items() if hits},
        "segmentation_iou_2_4m": {
            "n": len(seg),
            "median": round(float(np.median(seg)), 3) if seg else None,
            "p10": round(float(np.percentile(seg, 10)), 3) if seg else None,
        },
    }


def _frame_record(camera, joints, mask, distance: float, kind: str, name: str) -> dict:
    """A frame's ground truth: the person's box, projected joints, head and the two crops."""
    box = _box(mask)
    px = camera.project(joints)[0]
    head_px = px[JOINT_INDEX["head"]]
    side = int(1.25 * (box[3] - box[1]))
    cx, cy = (box[0] + box[2]) // 2, (box[1] + box[3]) // 2
    face_side = int(camera.fx * FACE_CROP_M / distance)
    return {
        "file": name,
        "kind": kind,
        "distance_m": round(distance, 3),
        "focal_px": camera.fx,
        "box": box,
        "joints_px": {joint: px[i].round(2).tolist() for joint, i in JOINT_INDEX.items()},
        "head_px": head_px.round(2).tolist(),
        "person_crop": [cx - side // 2, cy - side // 2, side],
        "face_crop": [int(head_px[0]) - face_side // 2, int(head_px[1]) - face_side // 2, face_side],
    }


def _joints(transforms: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World joints (24, 3) and the pelvis's forward direction from skinning transforms (24, 3, 4)."""
    joints = np.einsum("jab,jb->ja", transforms[:, :, :3], rest) + transforms[:, :, 3]
    return joints, transforms[JOINT_INDEX["pelvis"], :, :3] @ np.array([1.0, 0.0, 0.0])


def _viewpoint(joints: np.ndarray, forward: np.ndarray, distance: float, facing: float, kind: str):
    """The camera ``distance`` m from a person, ``facing`` rad from where its body faces (``forward``),
    looking at it: the robot camera for ``body`` frames, a level camera at head height otherwise."""
    from song.render import look_at

    angle = math.atan2(forward[1], forward[0]) + facing
    root = joints[JOINT_INDEX["pelvis"], :2]
    height = ROBOT_CAMERA_M if kind == "body" else float(joints[JOINT_INDEX["head"], 2])
    eye = np.array([*(root + distance * np.array([math.cos(angle), math.sin(angle)])), height])
    return look_at(eye, np.array([root[0], root[1], height]), WIDTH, HEIGHT, HFOV)


def _write_frame(out: Path, index: int, rgb: np.ndarray, mask: np.ndarray) -> str:
    """Write ``frame_NNNN.png`` and our person mask ``mask_NNNN.png``; the frame's file name."""
    import cv2

    name = f"frame_{index:04d}.png"
    cv2.imwrite(str(out / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(out / f"mask_{index:04d}.png"), mask.astype(np.uint8) * 255)
    return name


def portrait(asset, distance: float, facing_deg: float, kind: str, out: Path, index: int) -> dict:
    """One identity mid-stride (the procedural gait) in front of a plain wall colour, seen as a ``face`` /
    ``back`` frame (camera at the head joint's height) or a ``body`` frame (the robot camera); writes
    ``frame_NNNN.png`` and ``mask_NNNN.png`` into ``out`` and returns the frame's record."""
    from song.datasets.avatars.cache import skin_asset
    from song.geometry.fk import skinning_transforms
    from song.geometry.lbs import lbs_positions, lbs_rotations
    from song.render import GaussianSet, render
    from song.viz.avatar import walk_motion

    motion, frame = walk_motion(), 60
    scale = asset.height_m / float(motion.height_m)
    rest = asset.rest_joints.astype(np.float64)
    transforms = skinning_transforms(rest, motion.local_quats[frame], motion.root_pos[frame] * scale)
    skin = skin_asset(asset)
    g = asset.gaussians
    posed = GaussianSet.from_raw(
        lbs_positions(skin, transforms.astype(np.float32)),
        lbs_rotations(skin, transforms.astype(np.float32)),
        g.log_scales,
        g.opacity_logits,
        g.sh_dc,
    )
    joints, forward = _joints(transforms, rest)
    camera = _viewpoint(joints, forward, distance, math.radians(facing_deg), kind)
    frame_out = render([posed], camera, "numba", background=(0.62, 0.58, 0.52))
    mask = frame_out.alpha > 0.5
    name = _write_frame(out, index, frame_out.rgb, mask)
    return _frame_record(camera, joints, mask, distance, kind, name)


@functools.cache
def _skin_mst(asset_path: str) -> float | None:
    """The avatar's place on the Monk Skin Tone scale, from its generator metadata (None for other assets)."""
    from song.datasets.avatars import load_avatar

    return load_avatar(asset_path).meta.get("generator", {}).get("skin_mst")


def render_frames(bench_path: Path, out: Path, n_body: int, n_face: int, seed: int) -> list[dict]:
    """Render the ``body`` and ``face`` frames into ``out`` (PNG + our masks) and return their records."""
    from song.datasets.bench import open_benchmark
    from song.geometry.grid import world_to_cell
    from song.render import render
    from song.runtime.vision import SceneView

    bench = open_benchmark(str(bench_path))
    episodes = list(bench.episodes())
    view = SceneView("numba", "ideal")
    rng = np.random.default_rng(seed)
    frames: list[dict] = []
    wanted = [("body", n_body), ("face", n_face), ("back", n_face // 2)]
    for kind, count in wanted:
        made, tries = 0, 0
        while made < count and tries < 40 * count:
            tries += 1
            episode = episodes[int(rng.integers(len(episodes)))]
            if not episode.pedestrians:
                continue
            view.reset(episode)
            k = int(rng.integers(len(episode.pedestrians)))
            track = episode.pedestrians[k]
            t = float(rng.uniform(track.t[0], track.t[-1]))
            avatar = view._avatar(k)
            if avatar.posed is None:
                continue
            motion = avatar.posed.motion
            joints, forward = _joints(motion.transforms_at(t), motion.rest_joints.astype(np.float64))
            if kind == "body":
                d, phi = float(rng.uniform(2.0, 8.0)), math.radians(float(rng.uniform(-60, 60)))
            else:
                d, phi = float(rng.uniform(1.0, 2.5)), math.radians(float(rng.uniform(-15, 15)))
                phi += math.pi if kind == "back" else 0.0
            camera = _viewpoint(joints, forward, d, phi, kind)
            grid = episode.static_map
            free = grid.free
            r, c = world_to_cell(camera.position[None, :2], free.shape[0], grid.resolution, grid.origin)[0]
            if not (0 <= r < free.shape[0] and 0 <= c < free.shape[1]) or not free[r, c]:
                continue
            person = view.posed_avatars([k], t)
            alone = render(person[-1:], camera, "numba")
            full = render([view._scene, *person], camera, "numba")
            mask = alone.alpha > 0.5
            if mask.sum() < 50:
                continue
            hidden = (full.depth[mask] < alone.depth[mask] - 0.2).mean()
            if hidden > 0.05:
                continue
            name = _write_frame(out, len(frames), full.rgb, mask)
            record = _frame_record(camera, joints, mask, d, kind, name)
            binding = next((b for b in episode.avatars if b.ped_id == track.ped_id), None)
            frames.append(
                {
                    **record,
                    "episode": episode.episode_id,
                    "pedestrian": k,
                    "skin_mst": _skin_mst(binding.asset_path) if binding and binding.asset_path else None,
                    "t": round(t, 3),
                    "facing_deg": round(math.degrees(phi), 1),
                }
            )
            made += 1
    return frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--bench", default=str(ROOT / "runs" / "demo-bench"))
    parser.add_argument("--body", type=int, default=40)
    parser.add_argument("--faces", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(ROOT / "runs" / "bench-people"))
    parser.add_argument("--reuse", action="store_true", help="score the frames already in OUT (no rendering)")
    args = parser.parse_args()
    import cv2

    python = ensure_detectors()
    out = Path(args.out) / "frames"
    out.mkdir(parents=True, exist_ok=True)
    if args.reuse:
        frames = json.loads((out / "frames.json").read_text())
    else:
        for old in out.glob("*.png"):
            old.unlink()
        frames = render_frames(Path(args.bench), out, args.body, args.faces, args.seed)
        (out / "frames.json").write_text(json.dumps(frames, indent=1))
    subprocess.run([str(python), str(Path(__file__).with_name("_people_detect.py")), str(out)], check=True)
    detections = json.loads((out / "detections.json").read_text())
    masks = [cv2.imread(str(out / f"mask_{i:04d}.png"), cv2.IMREAD_GRAYSCALE) > 127 for i in range(len(frames))]
    segmented = [cv2.imread(str(out / f"seg_{i:04d}.png"), cv2.IMREAD_GRAYSCALE) > 127 for i in range(len(frames))]
    lumas = [
        face_luma(cv2.cvtColor(cv2.imread(str(out / f["file"])), cv2.COLOR_BGR2RGB), masks[i], f)
        if f["kind"] == "face"
        else None
        for i, f in enumerate(frames)
    ]
    record = {
        "bench": args.bench,
        "mediapipe": MEDIAPIPE_VERSION,
        "frames": {kind: sum(f["kind"] == kind for f in frames) for kind in ("body", "face", "back")},
        **score(frames, detections, masks, segmented, lumas),
        "targets": {
            "blazepose_found": 0.97,
            "blazepose_keypoints_within_10pct": 0.8,
            "face_mediapipe_short_1_2m": 0.7,
            "face_haar_1p5_2p5m": 0.5,
            "hog_2_8m": 0.95,
            "segmentation_iou_2_4m": 0.8,
        },
    }
    emit(record)


if __name__ == "__main__":
    main()
