"""Run the real-photo detectors on the frames ``benchmarks/people.py`` rendered (inside its own environment).

    build/bench-envs/people/bin/python benchmarks/_people_detect.py FRAMES_DIR

Reads ``FRAMES_DIR/frames.json`` (one record per frame: ``file``, and the ``face_crop`` / ``person_crop``
squares ``[x0, y0, side]`` in pixels) and the RGB frames ``frame_NNNN.png``; writes
``FRAMES_DIR/detections.json`` (per frame, in full-image pixels) and ``seg_NNNN.png`` (MediaPipe's
person mask on the frame, 255 = person, only inside the person crop). Nothing else is computed here:
the figures are made by ``benchmarks/people.py`` from these raw outputs.

Detectors (MediaPipe 0.10.21's bundled models through its ``solutions`` API, OpenCV's bundled ones):
- BlazePose (``pose``, model complexity 1, static images): 33 landmarks, x and y in pixels, visibility,
  on the whole frame (``pose``) and on the person crop (``pose_crop``);
- MediaPipe face detection, short range (``model_selection=0``) on the face crop;
- OpenCV's Haar frontal-face cascade (``haarcascade_frontalface_default.xml``, OpenCV's default
  parameters: scale 1.1, 3 neighbours) on the whole grey frame;
- OpenCV's HOG people detector (Dalal–Triggs default SVM; stride 8, padding 8, scale 1.05) on the frame;
- MediaPipe selfie segmentation (general model, ``model_selection=0``) on the person crop, mask > 0.5.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import mediapipe as mp
import numpy as np


def _crop(image: np.ndarray, box: list[int]) -> tuple[np.ndarray, int, int]:
    """The square ``[x0, y0, side]`` of the image (padded with black where it leaves the frame)."""
    x0, y0, side = box
    out = np.zeros((side, side, 3), np.uint8)
    h, w = image.shape[:2]
    xa, ya, xb, yb = max(x0, 0), max(y0, 0), min(x0 + side, w), min(y0 + side, h)
    if xb > xa and yb > ya:
        out[ya - y0 : yb - y0, xa - x0 : xb - x0] = image[ya:yb, xa:xb]
    return out, x0, y0


def main() -> None:
    folder = Path(sys.argv[1])
    frames = json.loads((folder / "frames.json").read_text())
    pose = mp.solutions.pose.Pose(static_image_mode=True, model_complexity=1)
    face = mp.solutions.face_detection.FaceDetection(model_selection=0, min_detection_confidence=0.5)
    segmenter = mp.solutions.selfie_segmentation.SelfieSegmentation(model_selection=0)
    haar = cv2.CascadeClassifier(cv2.data.haarcascades + "haarcascade_frontalface_default.xml")
    hog = cv2.HOGDescriptor()
    hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())
    out = []
    for index, frame in enumerate(frames):
        rgb = cv2.cvtColor(cv2.imread(str(folder / frame["file"])), cv2.COLOR_BGR2RGB)
        h, w = rgb.shape[:2]
        record: dict = {"file": frame["file"]}
        result = pose.process(rgb)
        record["pose"] = (
            None
            if result.pose_landmarks is None
            else [[p.x * w, p.y * h, p.visibility] for p in result.pose_landmarks.landmark]
        )
        crop, x0, y0 = _crop(rgb, frame["person_crop"])
        side = crop.shape[0]
        result = pose.process(crop)
        record["pose_crop"] = (
            None
            if result.pose_landmarks is None
            else [[x0 + p.x * side, y0 + p.y * side, p.visibility] for p in result.pose_landmarks.landmark]
        )
        crop, x0, y0 = _crop(rgb, frame["face_crop"])
        side = crop.shape[0]
        faces = []
        for det in face.process(crop).detections or []:
            box = det.location_data.relative_bounding_box
            faces.append(
                [x0 + box.xmin * side, y0 + box.ymin * side, box.width * side, box.height * side, det.score[0]]
            )
        record["face_short"] = faces
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        record["haar"] = [list(map(int, b)) for b in haar.detectMultiScale(grey, scaleFactor=1.1, minNeighbors=3)]
        boxes, weights = hog.detectMultiScale(rgb, winStride=(8, 8), padding=(8, 8), scale=1.05)
        record["hog"] = [[*map(int, b), float(s)] for b, s in zip(boxes, np.ravel(weights), strict=True)]
        crop, x0, y0 = _crop(rgb, frame["person_crop"])
        side = crop.shape[0]
        mask = segmenter.process(crop).segmentation_mask > 0.5
        full = np.zeros((h, w), np.uint8)
        xa, ya, xb, yb = max(x0, 0), max(y0, 0), min(x0 + side, w), min(y0 + side, h)
        full[ya:yb, xa:xb] = 255 * mask[ya - y0 : yb - y0, xa - x0 : xb - x0]
        cv2.imwrite(str(folder / f"seg_{index:04d}.png"), full)
        out.append(record)
    (folder / "detections.json").write_text(json.dumps(out))


if __name__ == "__main__":
    main()
