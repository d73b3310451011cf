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

MediaPipe and LiteRT write about a dozen INFO and WARNING lines of their own
to stderr when a landmarker starts, on its first frames and when it closes.
Unless `verbose=True` (the commands' `--verbose`), they are kept off stderr
while the landmarker is open (`rtcohand_drake.vision.library_log`).

A landmarker is closed by `close()`, by its `with` block, when it is
garbage-collected, or at the latest when the interpreter exits. MediaPipe
closes through a thread pool that Python shuts down before the `atexit`
handlers run, and its own finaliser fails later still (as modules are torn
down), so the landmarkers left open are closed from the threads' exit hook
(`threading._register_atexit`, where `concurrent.futures` registers its own),
which runs before the pool's.
"""

from __future__ import annotations

import dataclasses as dc
import threading
import weakref
from pathlib import Path

import numpy as np

from rtcohand_drake.errors import InputError
from rtcohand_drake.vision import library_log
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


def _close_landmarker(landmarker, hidden: bool) -> None:
    try:
        landmarker.close()
    finally:
        if hidden:
            library_log.release()


_OPEN: "weakref.WeakSet[HandLandmarker]" = weakref.WeakSet()
_exit_hook: list = []


def _close_open_landmarkers() -> None:
    for landmarker in list(_OPEN):
        landmarker.close()


def _close_at_exit(landmarker: "HandLandmarker") -> None:
    """Closes `landmarker` at exit if it is still open then (module docstring)."""
    _OPEN.add(landmarker)
    if not _exit_hook:
        # Registered after MediaPipe started its thread pool, so it runs before the pool's shutdown
        # (the hooks run last registered first).
        register = getattr(threading, "_register_atexit", None)  # CPython 3.9 and later
        if register is not None:
            register(_close_open_landmarkers)
        _exit_hook.append(_close_open_landmarkers)


def _import_mediapipe():
    try:
        import mediapipe as mp
        from mediapipe.tasks.python import BaseOptions, vision
    except ImportError as err:
        raise InputError(f"hand tracking needs MediaPipe, the optional extra: pip install -e \".[camera]\" ({err})") \
            from None
    return mp, BaseOptions, vision


class HandLandmarker:
    """One MediaPipe hand landmarker. `video=True`: frames of one stream, in time order (it tracks).

    `verbose`: let MediaPipe's own log lines through to stderr (module docstring)."""

    def __init__(self, config: Camera | None = None, video: bool = True, model: Path | None = None,
                 verbose: bool = False):
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
        self._last_ms = -1
        self._blur_sigma_px = config.blur_sigma_px
        self._blur_kernel_px = 2 * round(2 * config.blur_sigma_px) + 1
        if not verbose:
            library_log.hold()
        try:
            self._landmarker = vision.HandLandmarker.create_from_options(options)
        except BaseException as err:
            if not verbose:
                library_log.release()
            if isinstance(err, (RuntimeError, ValueError)):
                raise InputError(f"{path}: not a usable hand landmarker bundle: {err}") from None
            raise
        self._close = weakref.finalize(self, _close_landmarker, self._landmarker, not verbose)
        self._close.atexit = False  # too late then: `_close_at_exit`
        _close_at_exit(self)

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
        """Closes the landmarker (once; later calls do nothing)."""
        self._close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
