"""MediaPipe's hand landmarker, loaded from the bundle that ships with the package.

`models/hand_tracking/hand_landmarker.task` (see `models/README.md`, "Hand
tracking model") is read from disk: nothing is downloaded at run time.
MediaPipe is the optional extra `camera` (`pip install -e ".[camera]"`); it is
imported only when a landmarker is made, and its absence is a one-line
`InputError` naming the extra.

A detection gives, per hand: the 21 image landmarks in pixels, the 21 metric
"world" landmarks (metres, centred on the hand, camera axes: x right, y down,
z away from the camera), and MediaPipe's handedness label and score.

Each frame is blurred a little first (`Camera.blur_sigma_px`): on real
footage with pixel-level noise (a GIF's dithered palette) the palm detector
found no hand in two of ten clips, and after a Gaussian blur of 0.65 px
it finds one in 93-100 % of the frames of every clip (docs/own_hand.md).
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path

import numpy as np

from rtcohand_drake.errors import InputError
from rtcohand_drake.vision.config import Camera

MODEL_FILE = "hand_tracking/hand_landmarker.task"


def model_path() -> Path:
    from rtcohand_drake.cell.robot_files import models_dir

    return models_dir() / MODEL_FILE


@dc.dataclass(frozen=True)
class HandDetection:
    image_px: np.ndarray  # (21, 2) pixel coordinates (x right, y down)
    world_m: np.ndarray  # (21, 3) metres, hand-centred, camera axes
    handedness: str  # MediaPipe's label, "Left" or "Right" (for a mirrored, selfie-view image)
    score: float  # its confidence, 0..1

    @property
    def size_px(self) -> float:
        """The diagonal of the landmarks' bounding box, pixels."""
        return float(np.linalg.norm(self.image_px.max(axis=0) - self.image_px.min(axis=0)))


def _import_mediapipe():
    try:
        import mediapipe as mp
        from mediapipe.tasks.python import BaseOptions, vision
    except ImportError as err:
        raise InputError(f"hand tracking needs MediaPipe, the optional extra: pip install -e \".[camera]\" ({err})") \
            from None
    return mp, BaseOptions, vision


class HandLandmarker:
    """One MediaPipe hand landmarker. `video=True`: frames of one stream, in time order (it tracks)."""

    def __init__(self, config: Camera | None = None, video: bool = True, model: Path | None = None):
        mp, BaseOptions, vision = _import_mediapipe()
        path = Path(model) if model is not None else model_path()
        if not path.is_file():
            raise InputError(f"{path}: no hand landmarker model file")
        config = config or Camera()
        self._mp = mp
        self.video = video
        mode = vision.RunningMode.VIDEO if video else vision.RunningMode.IMAGE
        options = vision.HandLandmarkerOptions(
            base_options=BaseOptions(model_asset_buffer=path.read_bytes()), running_mode=mode,
            num_hands=config.num_hands, min_hand_detection_confidence=config.min_detection_confidence,
            min_hand_presence_confidence=config.min_presence_confidence,
            min_tracking_confidence=config.min_tracking_confidence)
        try:
            self._landmarker = vision.HandLandmarker.create_from_options(options)
        except (RuntimeError, ValueError) as err:
            raise InputError(f"{path}: not a usable hand landmarker bundle: {err}") from None
        self._last_ms = -1
        self._blur_sigma_px = config.blur_sigma_px
        self._blur_kernel_px = 2 * round(2 * config.blur_sigma_px) + 1

    def detect(self, frame_bgr: np.ndarray, time_s: float = 0.0) -> list[HandDetection]:
        """The hands in one BGR frame (OpenCV's order); `time_s` orders the frames of a video."""
        import cv2

        h, w = frame_bgr.shape[:2]
        rgb = cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2RGB)
        if self._blur_sigma_px > 0:
            k = self._blur_kernel_px
            rgb = cv2.GaussianBlur(rgb, (k, k), self._blur_sigma_px)
        image = self._mp.Image(image_format=self._mp.ImageFormat.SRGB, data=np.ascontiguousarray(rgb))
        if self.video:
            # MediaPipe needs strictly increasing whole milliseconds.
            ms = max(int(round(time_s * 1e3)), self._last_ms + 1)
            self._last_ms = ms
            result = self._landmarker.detect_for_video(image, ms)
        else:
            result = self._landmarker.detect(image)
        hands = []
        for marks, world, labels in zip(result.hand_landmarks, result.hand_world_landmarks, result.handedness):
            image_px = np.array([[m.x * w, m.y * h] for m in marks])
            world_m = np.array([[m.x, m.y, m.z] for m in world])
            best = max(labels, key=lambda c: c.score)
            hands.append(HandDetection(image_px, world_m, best.category_name, float(best.score)))
        return hands

    def close(self) -> None:
        self._landmarker.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
