"""`CameraGestureSource`: a camera's hand keypoints into the keypoint-source path to features.

Any object with `latest(now_s) -> (keypoints (21, 3) in metres in the user
frame or None, frame time s)` is a `HandTracker`; the source polls it each
policy period (`KeypointGestureSource` turns two successive skeletons into
features; a repeated frame time or a lost hand makes the gesture invalid and
the supervisor's watchdog takes over). The trackers, in
`rtcohand_drake.vision.capture`:

- `VideoFileTracker` (`--video PATH`): a video file played in simulated time
  at its own frame rate, the stand-in for a webcam; the run ends at its end
  unless `--duration` says otherwise;
- `LiveCameraTracker` (`--camera N`): an OpenCV camera, tracked in its own
  thread, each frame stamped at capture.

The calibration comes from `--camera-calibration FILE`
(`rtcohand_drake.vision.calibration`), or the defaults for a webcam facing
the person, with a warning. The tracker lives outside the diagram's context
(it is the outside world, like a camera), so a simulation with this source
is not re-entrant.
"""

from __future__ import annotations

import math

import sys
from typing import Protocol

import numpy as np

from rtcohand_drake.systems.gestures.base import NAN_HAND, KeypointGestureSource


class HandTracker(Protocol):
    """What a camera tracker provides (`rtcohand_drake.vision.capture`)."""

    def latest(self, now_s: float) -> tuple[np.ndarray | None, float]:
        """The newest hand skeleton (21, 3), metres, user frame (None if no hand) and its frame time (s),
        on the diagram's clock, given the diagram's time `now_s`."""


class CameraGestureSource(KeypointGestureSource):
    """A camera: polls a `HandTracker` each policy period (ports: `KeypointGestureSource`)."""

    def __init__(self, tracker: HandTracker, rate_hz: float = 10.0):
        super().__init__(rate_hz)
        self.tracker = tracker

    def keypoints_at(self, context) -> tuple[np.ndarray, float]:
        keypoints, frame_time = self.tracker.latest(context.get_time())
        return (NAN_HAND if keypoints is None else keypoints), float(frame_time)

    def close(self) -> None:
        """Releases the camera or file and the tracker (after the run)."""
        close = getattr(self.tracker, "close", None)
        if close is not None:
            close()


def make_tracker(scenario, camera: int | None = None, video=None, calibration_file=None, warn=None,
                 marker_tracker=None, verbose: bool = False):
    """The tracker for `--camera N` or `--video PATH` (exactly one), with the calibration (and an
    ArUco `marker_tracker` for the recorder's marker labels).

    A missing video file is reported before MediaPipe loads; if the tracker cannot be made, the
    landmarker already started is closed. `verbose`: MediaPipe's own log lines on stderr."""
    from pathlib import Path

    from rtcohand_drake.errors import InputError
    from rtcohand_drake.vision.calibration import DEFAULT_WARNING, CameraCalibration, load_calibration
    from rtcohand_drake.vision.capture import HandPipeline, LiveCameraTracker, VideoFileTracker

    calibration = load_calibration(calibration_file) if calibration_file is not None else None
    if video is not None and not Path(video).is_file():
        raise InputError(f"{video}: no such video file")
    if calibration is None:
        calibration = CameraCalibration()
        (warn or (lambda m: print(f"warning: {m}", file=sys.stderr)))(DEFAULT_WARNING)
    pipeline = HandPipeline(calibration, scenario.camera, video=True, marker_tracker=marker_tracker,
                            verbose=verbose)
    try:
        if video is not None:
            return VideoFileTracker(video, pipeline)
        return LiveCameraTracker(camera, pipeline)
    except BaseException:
        pipeline.close()
        raise


def from_options(options, scenario):
    """The `camera` source: `options.camera` (a device number) or `options.video` (a file)."""
    from rtcohand_drake.systems.gestures.registry import GestureSetup

    tracker = make_tracker(scenario, options.camera, options.video, options.camera_calibration,
                           verbose=getattr(options, "verbose", False))
    source = CameraGestureSource(tracker, scenario.policy.rate_hz)
    # A video file ends with the file; a live camera runs until Ctrl-C (an endless stream).
    return GestureSetup(source, None, getattr(tracker, "duration_s", math.inf))
