"""Frames in, hand keypoints out: a video file in simulated time, or a live camera in its own thread.

Both are `HandTracker`s (`rtcohand_drake.systems.gestures.camera`):
`latest(now_s)` gives the newest skeleton (21, 3) in metres in U, or None
when no hand is seen, and the time of its frame on the diagram's clock.

- `VideoFileTracker` plays a file at its own frame rate in simulated time:
  at diagram time t it shows frame floor(t * fps), at frame time index / fps,
  so a run at `--realtime-rate 0` sees exactly the frames a real-time run
  would. The file is the stand-in for a webcam (the tests and the benchmark
  use drawn-hand videos). After the last frame the frame time stops
  advancing, which the gesture source reads as a frozen stream.
- `LiveCameraTracker` reads a camera (OpenCV device number) in a thread, so
  the diagram never waits on the tracker. Each frame is stamped when
  `read()` returns it; the first `latest` call ties that clock to the
  diagram's. A camera that stops delivering, or repeats the same image,
  leaves the last time in place (frozen), a closed one too.

`HandPipeline` is the shared part: landmarks (MediaPipe), the hand to follow,
the metric fit, held steady in depth (`HandPoseFilter`), and into U. It records how long each frame took. Given a
`MarkerTracker` it also finds an ArUco-marked object's pose in U in each
frame (the recorder's `--labels aruco`): `marker()` on a tracker gives the
pose seen in the frame `latest` last returned.
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import numpy as np

from rtcohand_drake.errors import InputError
from rtcohand_drake.vision.calibration import CameraCalibration
from rtcohand_drake.vision.config import Camera
from rtcohand_drake.vision.hand_pose import choose_hand, keypoints_in_camera
from rtcohand_drake.vision.hand_pose_filter import HandPoseFilter
from rtcohand_drake.vision.landmarker import HandLandmarker


class HandPipeline:
    """One frame (BGR) to the followed hand's keypoints (21, 3) in U, or None."""

    def __init__(self, calibration: CameraCalibration, config: Camera | None = None, video: bool = True,
                 marker_tracker=None, verbose: bool = False):
        """`verbose`: MediaPipe's own log lines on stderr (`HandLandmarker`)."""
        self.calibration = calibration
        self.config = config or Camera()
        self.landmarker = HandLandmarker(self.config, video=video, verbose=verbose)
        self.pose_filter = HandPoseFilter(self.config.pose_filter)
        self.marker_tracker = marker_tracker
        self.last_marker = None  # (R_UM, p_UM) in the last frame processed, or None
        self.processing_s: list[float] = []  # per frame: frame in hand -> keypoints in U

    def process(self, frame_bgr: np.ndarray, time_s: float) -> np.ndarray | None:
        start = time.perf_counter()
        hand = choose_hand(self.landmarker.detect(frame_bgr, time_s), self.config)
        h, w = frame_bgr.shape[:2]
        keypoints = None
        if hand is not None:
            K = self.calibration.camera_matrix((w, h))
            points_C = keypoints_in_camera(hand, K, self.calibration.distortion_coefficients())
            if points_C is not None:
                points_C = self.pose_filter.steady(hand, points_C, K, time_s)
                keypoints = self.calibration.to_user_frame(points_C)
        self.processing_s.append(time.perf_counter() - start)
        if self.marker_tracker is not None:
            found = self.marker_tracker.pose_in_camera(frame_bgr, self.calibration.camera_matrix((w, h)),
                                                       self.calibration.distortion_coefficients())
            R_UC = self.calibration.R_UC()
            self.last_marker = None if found is None else (R_UC @ found[0],
                                                           self.calibration.to_user_frame(found[1][None])[0])
        return keypoints

    def close(self) -> None:
        self.landmarker.close()


def open_capture(source, what: str):
    """cv2.VideoCapture(source) (a camera number or a video file), or a one-line InputError. OpenCV's own
    log lines while it tries its back ends (a WARN or ERROR each, for a camera that is not there) are
    silenced; the error says what could not be opened."""
    import cv2

    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        capture = cv2.VideoCapture(source)
        opened = capture.isOpened()
    finally:
        cv2.utils.logging.setLogLevel(level)
    if not opened:
        raise InputError(f"{what}: cannot open it as a video stream")
    return capture


class VideoFileTracker:
    """A video file in simulated time (module docstring)."""

    def __init__(self, path, pipeline: HandPipeline):
        import cv2

        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: no such video file")
        self._pipeline = pipeline
        capture = open_capture(str(self.path), str(self.path))
        self.fps = float(capture.get(cv2.CAP_PROP_FPS))
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        capture.release()
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise InputError(f"{self.path}: the video has no frame rate")
        self.num_frames = count if count > 0 else None
        self._capture = None
        self._index = -1  # the frame last read
        self._result: tuple[np.ndarray | None, float] = (None, -math.inf)
        self._marker = None
        self._ended = False

    def marker(self):
        """The marked object's pose (R_UM, p_UM) in the frame `latest` last returned, or None."""
        return self._marker

    @property
    def duration_s(self) -> float | None:
        return None if self.num_frames is None else self.num_frames / self.fps

    def _rewind(self) -> None:
        if self._capture is not None:
            self._capture.release()
        self._capture = open_capture(str(self.path), str(self.path))
        self._index, self._ended = -1, False
        self._result = (None, -math.inf)

    def latest(self, now_s: float) -> tuple[np.ndarray | None, float]:
        wanted = int(math.floor(now_s * self.fps + 1e-6))
        if self._capture is None or wanted < self._index:
            self._rewind()
        if wanted == self._index or self._ended:
            return self._result
        while self._index < wanted - 1:  # frames between two policy updates are skipped, not decoded
            if not self._capture.grab():
                return self._end()
            self._index += 1
        ok, frame = self._capture.read()
        if not ok:
            return self._end()
        self._index += 1
        t = self._index / self.fps
        self._result = (self._pipeline.process(frame, t), t)
        self._marker = self._pipeline.last_marker
        return self._result

    def _end(self) -> tuple[np.ndarray | None, float]:
        self._ended = True
        self._result = (None, self._result[1])  # the frame time stays: the stream is closed
        self._marker = None
        return self._result

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()
        self._pipeline.close()


class LiveCameraTracker:
    """A camera read and tracked in its own thread (module docstring)."""

    def __init__(self, device, pipeline: HandPipeline):
        """`device`: an OpenCV camera number, or a path (a video file read as if it were a camera)."""
        self._pipeline = pipeline
        source = int(device) if isinstance(device, int) else str(device)
        self._capture = open_capture(source, f"camera {device}")
        self._lock = threading.Lock()
        self._latest: tuple[np.ndarray | None, float] = (None, -math.inf)  # keypoints, capture time (monotonic)
        self._marker = None  # the marked object's pose in that frame
        self._offset: float | None = None
        self._stop = threading.Event()
        self.closed = False
        self._thread = threading.Thread(target=self._loop, name="hand-tracker", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        previous = None
        while not self._stop.is_set():
            ok, frame = self._capture.read()
            stamp = time.monotonic()
            if not ok:
                break
            if previous is not None and np.array_equal(frame, previous):
                continue  # a driver repeating its last image: the stream is frozen, the time stays
            previous = frame
            keypoints = self._pipeline.process(frame, stamp)
            with self._lock:
                self._latest = (keypoints, stamp)
                self._marker = self._pipeline.last_marker
        with self._lock:
            self._latest = (None, self._latest[1])
        self.closed = True

    def marker(self):
        """The marked object's pose (R_UM, p_UM) in the newest frame, or None."""
        with self._lock:
            return self._marker

    def latest(self, now_s: float) -> tuple[np.ndarray | None, float]:
        if self._offset is None:
            self._offset = now_s - time.monotonic()
        with self._lock:
            keypoints, stamp = self._latest
        return keypoints, stamp + self._offset

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._capture.release()
        self._pipeline.close()
