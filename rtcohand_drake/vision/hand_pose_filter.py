"""A hand that holds still in depth: the person's hand size fixed, the palm's depth smoothed.

Each frame's metric fit (`hand_pose.keypoints_in_camera`) places MediaPipe's
metric hand where it covers the image landmarks, so the hand's depth is
proportional to the size MediaPipe guesses for it in that frame. On real
footage that guess varies by 2-18 % (one sigma) from frame to frame, which puts the
palm's depth through a range as wide as a swipe (docs/own_hand.md). Scaling
the camera-frame points about the camera's centre changes their depth and
leaves their image exactly as it was, so `HandPoseFilter` only chooses, per
frame, how far along its rays the hand lies:

1. **Fixed size** (`depth_cue`): the person's palm is measured once, as the
   median of MediaPipe's metric palm over the first `palm_size_from_first_s`
   of tracking, or given (`palm_size_m`), and kept for the run: it is the
   person's hand. Its rigid spans (wrist to each knuckle, index to pinky
   knuckle) do not bend, and a tilt only shortens a span's image, so the
   palm can be no further than the depth at which its least shortened span
   has its real length: "palm_spans" takes that depth. "fixed_palm" keeps
   the fit's depth, rescaled as if MediaPipe's hand had the person's palm
   size (its orientation still MediaPipe's guess); "fit" keeps the fit.
2. **Single-frame jumps**: a depth further from the last steady depth than
   `max_depth_speed_m_s` allows over the frame's interval (plus
   `jump_floor_m`) is replaced by it, for one frame at most, so a real move
   faster than that comes through one frame late.
3. **Smoothing** of that depth: a One Euro filter (Casiez, Roussel and Vogel,
   "1 Euro Filter", CHI 2012: a low-pass whose cutoff rises with the speed,
   so a still hand is smoothed hard and a moving one follows with little
   lag), or a constant-velocity Kalman filter, or none (`smoother`).

After `reset_after_s` without a hand, or when time goes back (a rewound
video), the depth starts afresh from the next frame.
"""

from __future__ import annotations

import math

import numpy as np

from rtcohand_drake.data.hand_features import PALM_POINTS
from rtcohand_drake.vision.config import PoseFilter
from rtcohand_drake.vision.landmarker import HandDetection

# Wrist to each knuckle, and index knuckle to pinky knuckle: the palm's rigid spans.
PALM_SPANS = np.array([(0, 5), (0, 9), (0, 13), (0, 17), (5, 17)])


def palm_spans(points: np.ndarray) -> np.ndarray:
    """The lengths (5,) of the palm's rigid spans, in the points' unit (metres, or pixels in an image)."""
    p = np.asarray(points, float)
    return np.linalg.norm(p[PALM_SPANS[:, 0]] - p[PALM_SPANS[:, 1]], axis=1)


def palm_size_m(points: np.ndarray) -> float:
    """The palm's size: the mean length of its rigid spans."""
    return float(palm_spans(points).mean())


def _alpha(cutoff_hz: float, dt: float) -> float:
    """The smoothing factor of a first-order low-pass with this cutoff, sampled every dt."""
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau / dt)


class OneEuro:
    """The One Euro filter on one signal (Casiez et al. 2012, the module docstring)."""

    def __init__(self, config: PoseFilter, value: float):
        self.config = config
        self.value, self.speed = value, 0.0

    def update(self, value: float, dt: float) -> float:
        c = self.config
        self.speed += _alpha(c.derivative_cutoff_hz, dt) * ((value - self.value) / dt - self.speed)
        cutoff = c.min_cutoff_hz + c.beta_hz_per_m_s * abs(self.speed)
        self.value += _alpha(cutoff, dt) * (value - self.value)
        return self.value


class ConstantVelocityKalman:
    """A Kalman filter on depth and its speed, driven by white random acceleration."""

    def __init__(self, config: PoseFilter, value: float):
        self.q, self.r = config.kalman_accel_m_s2 ** 2, config.kalman_depth_noise_m ** 2
        self.x = np.array([value, 0.0])
        # The first frame's depth is as uncertain as any; its speed is unknown (1 m/s, one sigma).
        self.P = np.diag([self.r, 1.0])

    def update(self, value: float, dt: float) -> float:
        F = np.array([[1.0, dt], [0.0, 1.0]])
        Q = self.q * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
        x, P = F @ self.x, F @ self.P @ F.T + Q
        gain = P[:, 0] / (P[0, 0] + self.r)
        self.x = x + gain * (value - x[0])
        self.P = P - np.outer(gain, P[0])
        return float(self.x[0])


class Unsmoothed:
    """No smoothing: the depth as measured."""

    def __init__(self, config: PoseFilter, value: float):
        pass

    def update(self, value: float, dt: float) -> float:
        return value


SMOOTHERS = {"one_euro": OneEuro, "kalman": ConstantVelocityKalman, "none": Unsmoothed}


class HandPoseFilter:
    """Steadies one hand's depth, frame by frame (module docstring)."""

    def __init__(self, config: PoseFilter | None = None):
        self.config = config or PoseFilter()
        if self.config.smoother not in SMOOTHERS:
            raise ValueError(f"unknown smoother {self.config.smoother!r}")
        if self.config.depth_cue not in DEPTH_CUES:
            raise ValueError(f"unknown depth cue {self.config.depth_cue!r}")
        self._spans: list[np.ndarray] = []  # MediaPipe's palm spans over the first seconds of tracking
        self._first_time: float | None = None
        self.reset()

    def reset(self) -> None:
        """Forgets the depth (not the person's palm)."""
        self._smoother = None
        self._last_time: float | None = None
        self._last_depth = math.nan
        self._held = False  # the last frame's depth was a rejected jump

    def person_spans_m(self) -> np.ndarray | None:
        """The person's palm spans (5,), metres, or None before a hand has been seen."""
        if not self._spans:
            return None
        spans = np.median(self._spans, axis=0)
        if self.config.palm_size_m > 0:
            spans *= self.config.palm_size_m / spans.mean()
        return spans

    def _learn_palm(self, world_m: np.ndarray, time_s: float) -> None:
        spans = palm_spans(world_m)
        if not (np.all(np.isfinite(spans)) and spans.min() > 0):
            return
        if self._first_time is None:
            self._first_time = time_s
        if not self._spans or time_s - self._first_time <= self.config.palm_size_from_first_s:
            self._spans.append(spans)

    def steady(self, detection: HandDetection, points_C: np.ndarray, camera_matrix: np.ndarray,
               time_s: float) -> np.ndarray:
        """The hand's points (21, 3) in the camera frame, moved along their rays to the steady depth.

        `detection`: MediaPipe's landmarks of the frame; `points_C`: their metric fit
        (`hand_pose.keypoints_in_camera`); `time_s`: the frame's time (s), increasing along a stream.
        """
        c = self.config
        points_C = np.asarray(points_C, float)
        if not c.enabled:
            return points_C
        depth = float(points_C[PALM_POINTS, 2].mean())
        if self._last_time is not None and (time_s < self._last_time or time_s - self._last_time > c.reset_after_s):
            self.reset()
        if self._last_time is not None and time_s == self._last_time:
            return points_C * (self._last_depth / depth)  # the same frame again
        self._learn_palm(detection.world_m, time_s)
        measured = DEPTH_CUES[c.depth_cue](depth, detection, np.asarray(camera_matrix, float), self.person_spans_m())
        if not (math.isfinite(measured) and measured > 0):
            measured = depth
        if self._smoother is None:
            self._smoother = SMOOTHERS[c.smoother](c, measured)
            steady = measured
        else:
            dt = time_s - self._last_time
            # Compared with the last steady depth, not a prediction: a jump's speed must not carry on.
            if not self._held and abs(measured - self._last_depth) > c.max_depth_speed_m_s * dt + c.jump_floor_m:
                self._held = True
                measured = self._last_depth
            else:
                self._held = False
            steady = self._smoother.update(measured, dt)
        self._last_time, self._last_depth = time_s, steady
        return points_C * (steady / depth)


def fit_depth(depth, detection, camera_matrix, person_spans_m) -> float:
    """The metric fit's own depth: MediaPipe's size for the hand in this frame."""
    return depth


def fixed_palm_depth(depth, detection, camera_matrix, person_spans_m) -> float:
    """The fit's depth as if MediaPipe's hand had the person's palm size (a fit scales with its model)."""
    return depth * float(person_spans_m.mean()) / palm_size_m(detection.world_m)


def palm_spans_depth(depth, detection, camera_matrix, person_spans_m) -> float:
    """The depth at which the least shortened palm span has the person's length (weak perspective:
    the palm is small beside its distance; lens distortion is neglected)."""
    K = camera_matrix
    rays = (detection.image_px - K[:2, 2]) / np.diag(K)[:2]  # image points at unit depth
    with np.errstate(divide="ignore"):  # a span seen end-on: infinite, never the least
        return float(np.min(person_spans_m / palm_spans(rays)))


DEPTH_CUES = {"palm_spans": palm_spans_depth, "fixed_palm": fixed_palm_depth, "fit": fit_depth}


def crossing_time_s(times: np.ndarray, signal: np.ndarray, level: float) -> float:
    """When `signal` first reaches `level` (from below or above), linearly interpolated between samples."""
    s = np.asarray(signal, float) - level
    for k in range(1, len(s)):
        if s[k - 1] * s[k] <= 0 and s[k - 1] != 0:
            return float(times[k - 1] + (times[k] - times[k - 1]) * s[k - 1] / (s[k - 1] - s[k]))
    return math.inf


def depth_lag_s(config: PoseFilter, rate_hz: float = 10.0, rise_s: float = 0.0, move_m: float = 0.10) -> float:
    """The filter's added lag on a hand that moves `move_m` toward the camera at 1 s.

    A still hand 0.3 m from the camera, seen at `rate_hz`, moves `move_m` in depth
    along a smooth step lasting `rise_s` (0: a jump); the lag is how much later the
    filtered palm depth crosses half the move than the unfiltered one.
    """
    from rtcohand_drake.vision.calibration import CameraCalibration
    from rtcohand_drake.vision.drawn_hand import open_hand_U, project

    calibration = CameraCalibration()
    K = calibration.camera_matrix()
    hand_C = (open_hand_U((0.0, 0.2, 0.0)) - calibration.p_UC()) @ calibration.R_UC()
    world_m = hand_C - hand_C.mean(axis=0)
    times = np.arange(int(3.0 * rate_hz)) / rate_hz
    u = np.clip((times - 1.0) / rise_s, 0.0, 1.0) if rise_s > 0 else (times >= 1.0).astype(float)
    moved = -move_m * u * u * (3.0 - 2.0 * u)  # smoothstep: no speed at either end
    steady = HandPoseFilter(config)
    raw, filtered = [], []
    for t, dz in zip(times, moved):
        points_C = hand_C + [0.0, 0.0, dz]
        seen = HandDetection(project(points_C, K), world_m, "Left", 1.0)
        raw.append(points_C[PALM_POINTS, 2].mean())
        filtered.append(steady.steady(seen, points_C, K, t)[PALM_POINTS, 2].mean())
    half = raw[0] - move_m / 2
    return crossing_time_s(times, filtered, half) - crossing_time_s(times, raw, half)
