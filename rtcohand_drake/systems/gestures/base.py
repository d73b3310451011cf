"""The base of every gesture source, and the output ports they share.

Every source has the same output ports (`rtcohand_drake.interfaces`):
  gesture_features (36) hand-part velocities at the policy rate, user frame
                        (see `rtcohand_drake.data.hand_features`); zeros when the hand is lost
  gesture_status   (2)  [valid (0/1), time of the frame the features come from (s)]
  keypoints        (63) the current 21-point hand skeleton, metres, user frame,
                        row-major (NaN when the hand is lost); for drawing

`KeypointGestureSource` is the base of every live source. Each policy period
it asks `keypoints_at(t)` for the newest skeleton and its frame time, and
turns two successive skeletons into features. A repeated frame time (a frozen
camera) or a lost hand makes the features invalid. The sources themselves
(`replay`, `camera`, `simulated_person`) register under a name in
`rtcohand_drake.systems.gestures.registry`.
"""

from __future__ import annotations



import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.data.hand_features import part_frames, part_velocities
from rtcohand_drake.interfaces import FEATURE_DIM, GESTURE_FEATURES, GESTURE_STATUS, KEYPOINTS, KEYPOINTS_DIM

NAN_HAND = np.full((21, 3), np.nan)


class KeypointGestureSource(LeafSystem):
    """Base of the live sources: skeletons in, features out, at the policy rate.

    Subclasses implement `keypoints_at(context) -> (keypoints (21, 3), frame_time)`.
    Discrete state: the previous skeleton and its time, the features and status.
    """

    def __init__(self, rate_hz: float = 10.0):
        super().__init__()
        self.period_s = 1.0 / rate_hz
        self._last_frames = None  # (skeleton, its part frames): see `_part_frames`
        self._prev = self.DeclareDiscreteState(np.concatenate([NAN_HAND.reshape(-1), [np.nan]]))
        self._features = self.DeclareDiscreteState(FEATURE_DIM)
        self._status = self.DeclareDiscreteState(np.array([0.0, -np.inf]))
        self.DeclarePeriodicDiscreteUpdateEvent(self.period_s, 0.0, self._update)
        self.DeclareStateOutputPort(GESTURE_FEATURES, self._features)
        self.DeclareStateOutputPort(GESTURE_STATUS, self._status)
        self.DeclareVectorOutputPort(KEYPOINTS, KEYPOINTS_DIM, self._calc_keypoints,
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
            R0, o0 = self._part_frames(kp_prev)
            R1, o1 = self._part_frames(kp)
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

    def _part_frames(self, kp: np.ndarray):
        """`part_frames` of one skeleton; the last skeleton's are kept, since each update's previous
        skeleton is the one before's current (a cache keyed by the values, so any context may use it)."""
        cached = self._last_frames
        if cached is not None and np.array_equal(cached[0], kp):
            return cached[1], cached[2]
        R, o = part_frames(kp)
        self._last_frames = (kp.copy(), R, o)
        return R, o

    def _calc_keypoints(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._prev).get_value()[:63])
