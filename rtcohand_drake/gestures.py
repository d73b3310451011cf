"""Gesture sources: systems that output what the policy reads.

Every source has the same output ports:
  gesture_features (36) hand-part velocities at the policy rate, user frame
                        (see `rtcohand_drake.hand_features`); zeros when the hand is lost
  gesture_status   (2)  [valid (0/1), time of the frame the features come from (s)]
  keypoints        (63) the current 21-point hand skeleton, metres, user frame,
                        row-major (NaN when the hand is lost); for drawing

Sources:
- `ReplayGestureSource`: plays dataset clips (contracts §1) back to back, with
  exactly the features the offline pipeline computes for them.
- `KeypointGestureSource`: the base of every live source. Each policy period
  it asks `keypoints_at(t)` for the newest skeleton and its frame time, and
  turns two successive skeletons into features. A repeated frame time (a
  frozen camera) or a lost hand makes the features invalid.
- `CameraGestureSource`: the interface a live camera plugs into: any object
  with `latest() -> (keypoints (21, 3) in the user frame or None, frame time s)`.
- The simulated operator (`rtcohand_drake.operator_sim`) is a keypoint source too.
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.hand_features import part_frames, part_velocities

NAN_HAND = np.full((21, 3), np.nan)


class ReplayGestureSource(LeafSystem):
    """Replays clips at the policy rate (features computed offline, exactly as in training).

    `clips` are `PolicyClip`s; `skeletons` (optional) are per-clip keypoint
    arrays resampled at the policy rate, for drawing. After the last clip the
    source reports an invalid gesture (the supervisor's watchdog then stops the arm).
    """

    def __init__(self, clips: Sequence, rate_hz: float = 10.0, skeletons: Sequence[np.ndarray] | None = None):
        super().__init__()
        if not clips:
            raise ValueError("ReplayGestureSource needs at least one clip")
        self._rate = rate_hz
        self._features = np.concatenate([c.features for c in clips]).astype(float)
        self._valid = np.concatenate([c.valid for c in clips]).astype(float)
        self._labels = (np.concatenate([c.labels for c in clips]) if all(c.labels is not None for c in clips)
                        else None)
        self.clip_starts = np.cumsum([0] + [len(c) for c in clips])[:-1] / rate_hz
        self.clip_names = [c.name for c in clips]
        self._skeletons = (np.concatenate([np.asarray(s, float).reshape(len(s), 63) for s in skeletons])
                           if skeletons is not None else None)
        self.DeclareVectorOutputPort("gesture_features", 36, self._calc_features)
        self.DeclareVectorOutputPort("gesture_status", 2, self._calc_status)
        self.DeclareVectorOutputPort("keypoints", 63, self._calc_keypoints)

    @property
    def end_time(self) -> float:
        return len(self._features) / self._rate

    @property
    def features(self) -> np.ndarray:
        return self._features

    @property
    def labels(self) -> np.ndarray | None:
        return self._labels

    def _index(self, context) -> int:
        return int(np.floor(context.get_time() * self._rate + 1e-6))

    def _calc_features(self, context, output: BasicVector):
        k = self._index(context)
        output.SetFromVector(self._features[k] if k < len(self._features) else np.zeros(36))

    def _calc_status(self, context, output: BasicVector):
        k = self._index(context)
        if k < len(self._features):
            output.SetFromVector([self._valid[k], k / self._rate])
        else:  # the stream has ended: no fresh gesture
            output.SetFromVector([0.0, (len(self._features) - 1) / self._rate])

    def _calc_keypoints(self, context, output: BasicVector):
        k = self._index(context)
        if self._skeletons is not None and k < len(self._skeletons):
            output.SetFromVector(self._skeletons[k])
        else:
            output.SetFromVector(NAN_HAND.reshape(-1))


class KeypointGestureSource(LeafSystem):
    """Base of the live sources: skeletons in, features out, at the policy rate.

    Subclasses implement `keypoints_at(context) -> (keypoints (21, 3), frame_time)`.
    Discrete state: the previous skeleton and its time, the features and status.
    """

    def __init__(self, rate_hz: float = 10.0):
        super().__init__()
        self.period_s = 1.0 / rate_hz
        self._prev = self.DeclareDiscreteState(np.concatenate([NAN_HAND.reshape(-1), [np.nan]]))
        self._features = self.DeclareDiscreteState(36)
        self._status = self.DeclareDiscreteState(np.array([0.0, -np.inf]))
        self.DeclarePeriodicDiscreteUpdateEvent(self.period_s, 0.0, self._update)
        self.DeclareStateOutputPort("gesture_features", self._features)
        self.DeclareStateOutputPort("gesture_status", self._status)
        self.DeclareVectorOutputPort("keypoints", 63, self._calc_keypoints,
                                     prerequisites_of_calc={self.xd_ticket()})

    def keypoints_at(self, context) -> tuple[np.ndarray, float]:
        raise NotImplementedError

    def _update(self, context, discrete_state):
        prev = context.get_discrete_state(self._prev).get_value()
        kp_prev, t_prev = prev[:63].reshape(21, 3), prev[63]
        kp, t_frame = self.keypoints_at(context)
        kp = np.asarray(kp, float).reshape(21, 3)
        features, valid = np.zeros(36), False
        if np.isfinite(t_frame) and np.isfinite(t_prev) and t_frame > t_prev \
                and np.all(np.isfinite(kp)) and np.all(np.isfinite(kp_prev)):
            R0, o0 = part_frames(kp_prev)
            R1, o1 = part_frames(kp)
            x = part_velocities(R0, o0, R1, o1, t_frame - t_prev)
            if np.all(np.isfinite(x)):
                features, valid = x, True
        status = context.get_discrete_state(self._status).get_value()
        fresh = np.isfinite(t_frame) and not (np.isfinite(t_prev) and t_frame <= t_prev)
        # The status carries the time of the newest frame seen; a frozen feed keeps an old time.
        frame_time = float(t_frame) if fresh else status[1]
        discrete_state.set_value(self._features, features)
        discrete_state.set_value(self._status, [1.0 if valid else 0.0, frame_time])
        if fresh:
            discrete_state.set_value(self._prev, np.concatenate([kp.reshape(-1), [t_frame]]))

    def _calc_keypoints(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._prev).get_value()[:63])


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
