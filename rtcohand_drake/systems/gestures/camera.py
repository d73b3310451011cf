"""`CameraGestureSource`: the interface a live camera plugs into.

Any object with `latest() -> (keypoints (21, 3) in the user frame or None,
frame time s)` is a `HandTracker`; the source polls it each policy period.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from rtcohand_drake.errors import InputError

from rtcohand_drake.systems.gestures.base import NAN_HAND, KeypointGestureSource


class HandTracker(Protocol):
    """What a live camera tracker provides (e.g. MediaPipe Hands behind a webcam)."""

    def latest(self) -> tuple[np.ndarray | None, float]:
        """The newest hand skeleton (21, 3) in metres in the user frame (None if no hand) and its time (s)."""


class CameraGestureSource(KeypointGestureSource):
    """A live camera: polls a `HandTracker` each policy period."""

    def __init__(self, tracker: HandTracker, rate_hz: float = 10.0):
        super().__init__(rate_hz)
        self.tracker = tracker

    def keypoints_at(self, context) -> tuple[np.ndarray, float]:
        keypoints, frame_time = self.tracker.latest()
        return (NAN_HAND if keypoints is None else keypoints), float(frame_time)


def from_options(options, scenario):
    """The `camera` source: no tracker ships in this build, so this is a clear one-line error."""
    raise InputError("command line: --gesture-source camera needs a live hand tracker "
                     "(pip install -e '.[camera]'); none is connected in this build")
