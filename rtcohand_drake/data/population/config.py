"""Every number of the population generator, with its unit (`GeneratorConfig`), and the default population."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass


# The population `python -m rtcohand_drake.data.generate` writes by default (the benchmark's).
DEFAULT_USERS = 15
DEFAULT_SEED = 0



@dataclass
class GeneratorConfig:
    """Every generator number. Pairs ``(lo, hi)`` are uniform ranges."""

    fps: float = 30.0  # Hz, keypoint frame rate (camera-like)
    in_sample_fraction: float = 2.0 / 3.0  # share of users that are in-sample (10 of 15)
    clip_duration_s: tuple[float, float] = (3.6, 5.0)  # clip length; at most 5 s (paper)
    onset_s: tuple[float, float] = (0.3, 0.7)  # rest before the gesture starts
    ramp_s: tuple[float, float] = (0.2, 0.45)  # gesture ramp up / down
    tail_s: tuple[float, float] = (0.9, 1.3)  # rest after the gesture, for the handler to stop
    second_onset_jitter_s: float = 0.15  # two-dimension clips: onset offset of the second gesture
    # User variety
    hand_scale: tuple[float, float] = (0.88, 1.12)  # bone lengths relative to an adult hand
    rest_position_m: tuple[tuple[float, float], ...] = ((0.05, 0.2), (0.25, 0.4), (-0.1, 0.05))
    rest_yaw_deg: float = 10.0  # +- yaw of the reference gesture
    translation_speed_m_s: tuple[float, float] = (0.06, 0.15)  # hand speed in move gestures
    rotation_rate_rad_s: tuple[float, float] = (0.3, 0.6)  # wrist rate in turn gestures
    max_turn_rad: float = 1.3  # wrist range: turns saturate smoothly here
    max_excursion_m: float = 0.35  # arm range: moves saturate smoothly here
    p_repeated_rhythm: float = 0.4  # share of users who gesture in repeated strokes
    stroke_freq_hz: tuple[float, float] = (0.8, 1.6)  # repeated strokes
    stroke_amplitude: tuple[float, float] = (1.3, 2.2)  # stroke speed relative to the net drift
    # Users who make each move or turn as one stroke, out and partly back, short and fast, as recorded
    # people do (docs/real_people.md, "Recorded hands against simulated ones": 1.7 s, a third of the
    # way back and three times as fast, medians). 0: nobody (the default population is unchanged).
    p_single_stroke: float = 0.0
    single_stroke_s: tuple[float, float] = (1.1, 2.5)  # the stroke's duration (recorded: 25-75 %)
    single_stroke_return: tuple[float, float] = (0.0, 1.0)  # how far back it comes (0 one way, 1 all the way)
    single_stroke_speed_gain: tuple[float, float] = (2.0, 4.0)  # peak speed against the user's steady speed
    # Users who make every motion the direct way: each move a move of the hand along its axis, each turn a
    # turn of the wrist about its axis (each dimension's first strategy), with the signs (mirroring, flips)
    # they drew. A linear map of the hand's motion reads such a person closely. 0: nobody (the default
    # population is unchanged).
    p_direct: float = 0.0
    p_curled_posture: float = 0.3  # share of users who curl the fingers while gesturing
    p_turn_about_elbow: float = 0.35  # share of users who turn about the elbow (hand moves)
    elbow_offset_m: tuple[float, float] = (0.18, 0.26)  # elbow behind the wrist
    finger_sweep_amplitude: tuple[float, float] = (0.2, 0.35)  # curl level (0 flat .. 1 fist)
    spread_sweep_amplitude_rad: tuple[float, float] = (0.2, 0.35)
    thumb_sweep_amplitude_rad: tuple[float, float] = (0.25, 0.4)
    finger_sweep_freq_hz: tuple[float, float] = (1.0, 1.8)
    curl_rate_per_s: tuple[float, float] = (0.35, 0.6)  # curl level per second
    relaxed_curl: tuple[float, float] = (0.15, 0.3)  # reference gesture curl level
    p_mirrored: float = 0.4  # share of users who think from the robot's side (X, Y flipped)
    p_flip_dimension: float = 0.2  # chance each dimension's sign is flipped on its own
    intensity_log_sd: float = 0.15  # per-clip gesture intensity (log-normal)
    tremor_position_m: tuple[float, float] = (0.0005, 0.002)  # amplitude, per axis
    tremor_rotation_rad: tuple[float, float] = (0.002, 0.008)
    tremor_freq_hz: tuple[float, float] = (8.0, 12.0)
    wander_position_m: float = 0.004  # slow hand wander amplitude
    # Camera / detector
    jitter_m: float = 0.001  # Gaussian detector noise on every keypoint coordinate
    dropout_prob: float = 0.02  # chance a frame is lost on its own
    burst_prob: float = 0.004  # chance a burst of lost frames starts at a frame
    burst_frames: tuple[int, int] = (3, 10)  # burst length range, frames
    # Tracking glitches: a frame (or a few) where the tracker puts the hand off by centimetres, as a
    # depth camera's skeleton tracker does now and then. The whole hand shifts by one vector, plus a
    # share of that size on each keypoint alone. 0: none (and nothing is drawn for them).
    glitch_prob: float = 0.0  # chance a glitch starts at a frame
    glitch_m: tuple[float, float] = (0.005, 0.05)  # its size, log-uniform
    glitch_frames: tuple[int, int] = (1, 2)  # its length, frames
    glitch_keypoint_share: float = 0.3  # each keypoint's own part, against the whole hand's shift
    # Handler (labels)
    handler_delay_s: tuple[float, float] = (0.15, 0.35)  # reaction delay
    handler_lag_s: tuple[float, float] = (0.15, 0.35)  # first-order smoothing time constant
    handler_speed_m_s: tuple[float, float] = (0.06, 0.13)  # nominal object speed
    handler_rate_rad_s: tuple[float, float] = (0.35, 0.8)  # nominal object turn rate
    handler_follow_exponent: float = 0.5  # label magnitude ~ intensity ** exponent
    handler_misjudge_log_sd: float = 0.15  # per-clip magnitude misjudgement (log-normal)
    handler_crosstalk: float = 0.04  # leak into inactive dimensions, fraction of magnitude
    tracking_noise_m_s: float = 0.004  # marker-tracking noise on linear velocity
    tracking_noise_rad_s: float = 0.015  # on angular velocity
    object_start_position_m: tuple[float, float, float] = (0.0, 0.55, 0.0)

    def to_json(self) -> str:
        return json.dumps(asdict(self))


# Tracking as measured on recorded people (docs/real_people.md, "Recorded hands against simulated
# ones"; chosen on the SHREC'17 development subjects' statistics): a tracker that is steadier frame to
# frame than the default's (the palm's median single-frame residual 0.3-0.4 mm, against 1.6-1.8 mm) but
# glitches by centimetres now and then (its 99th percentile 16-18 mm, against 4 mm).
# `generate --recorded-tracking` applies it over the defaults.
RECORDED_TRACKING = {
    "jitter_m": 0.0002,
    "tremor_position_m": (0.0001, 0.0004),
    "glitch_prob": 0.03,
    "glitch_m": (0.003, 0.07),
    "glitch_frames": (1, 4),
}
