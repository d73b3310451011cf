"""Simulated users: gesture strategies, an anatomical hand model, and a human handler's labels.

The generator follows the CCHP paper's data protocol: users (two thirds
in-sample, one third out-sample; 10 and 5 of 15), 72 clips each of at most
5 s, 24 with one active dimension (6 dimensions x 2 signs x 2) and 48 with
two, split as in the paper's appendix (see :func:`clip_design`).

Users
-----
Each user (:class:`UserProfile`) maps each of the 12 motions (dimension, sign)
to a gesture (:class:`Gesture`). For each dimension the user picks one
strategy among those people use for it (``STRATEGIES``): move the hand along
an axis, point and move, turn or tilt the wrist, turn while moving, sweep the
fingers (flex, spread or thumb flick, the sign carried by which stroke is
fast), or curl/uncurl the fingers. The opposite sign is the opposite gesture.
A user's 6 gestures never share an axis of motion or a finger pattern, so
each user is unambiguous; across users they conflict: a mirrored user
(thinking from the robot's side) flips X and Y, any dimension may be flipped
on its own, and the same gesture (say "move the hand up") stands for Tz for
one user and Rx for another. A user also has a hand size, a speed and turn
rate, a rhythm (steady, or repeated strokes with a net drift), a finger
posture while gesturing (extended or curled), a rotation style (turn in
place about the palm, or about the elbow, so the hand moves while turning) and
a tremor.

Hand model
----------
A right hand with fixed bone lengths (scaled per user) and joint angles in
anatomical ranges (finger MCP -13..85 deg, PIP 0..100 deg, DIP 0..70 deg,
abduction within +-25 deg; thumb in its own ranges) is posed by forward
kinematics, then placed by a wrist pose. Every clip starts from the reference
initial gesture: palm down, fingers forward, relaxed (slightly curled). Camera
effects: Gaussian detector jitter on every keypoint, single dropped frames
and short dropout bursts (all-NaN frames).

Labels
------
A handler moves a tracked object in response: the label of an active
dimension is the gesture's intent (its activation envelope, with the user's
sign) delayed by a reaction delay (150-350 ms), smoothed by a first-order lag,
scaled by a magnitude that follows the gesture's intensity only partly and is
misjudged (log-normal), with cross-talk into the other dimensions and
tracking noise. The object pose integrates the labelled twist.

Every number is a field of :class:`GeneratorConfig`, with its unit.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from rtcohand_drake.data.dataset import DIMENSIONS, Clip

# --------------------------------------------------------------------------- config


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


# --------------------------------------------------------------------------- clip design


def clip_design(rng: np.random.Generator, in_sample: bool) -> list[tuple[tuple[tuple[int, int], ...], str]]:
    """The 72 clips of a user: (((dim, sign), ...), split), in a shuffled order.

    24 one-dimension clips (6 dims x 2 signs x 2), one of each pair in train
    and one in test. 48 two-dimension clips: 3 of the 15 dimension pairs are
    test-only (4 sign combinations each: 12 clips); each of the other 12 pairs
    has 3 of its 4 sign combinations, 2 in train and 1 in test. So train and
    test hold 36 clips each; 24 two-dimension clips each, and half of the test
    two-dimension clips use pairs also seen in train (paper, appendix). An
    out-sample user has the same clips, all "test".
    """
    clips: list[tuple[tuple[tuple[int, int], ...], str]] = []
    for d in range(6):
        for s in (1, -1):
            first = rng.integers(2)
            for rep in range(2):
                clips.append((((d, s),), "train" if rep == first else "test"))
    pairs = [(i, j) for i in range(6) for j in range(i + 1, 6)]
    order = rng.permutation(len(pairs))
    new_pairs = {pairs[k] for k in order[:3]}
    signs = [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    for pair in pairs:
        if pair in new_pairs:
            for s in signs:
                clips.append((((pair[0], s[0]), (pair[1], s[1])), "test"))
        else:
            chosen = rng.permutation(4)[:3]
            for n, k in enumerate(chosen):
                s = signs[k]
                clips.append((((pair[0], s[0]), (pair[1], s[1])), "train" if n < 2 else "test"))
    if not in_sample:
        clips = [(m, "test") for m, _ in clips]
    return [clips[k] for k in rng.permutation(len(clips))]


# --------------------------------------------------------------------------- gestures

AXES = np.eye(3)
# Strategies per dimension: (kind, axis index, extra, weight). Axis is the
# natural one; "extra" is the translation axis of turn_move or the finger pattern.
STRATEGIES: dict[int, list[tuple[str, int, int | str | None, float]]] = {
    0: [("move", 0, None, 3.0), ("point", 0, None, 1.0), ("turn", 2, None, 1.0), ("sweep", -1, "spread", 1.0)],
    1: [("move", 1, None, 3.0), ("point", 1, None, 1.0), ("sweep", -1, "flex", 1.5), ("turn", 0, None, 1.0),
        ("curl", -1, None, 0.5)],
    2: [("move", 2, None, 3.0), ("point", 2, None, 1.0), ("turn", 0, None, 1.0), ("curl", -1, None, 1.0),
        ("sweep", -1, "flex", 0.5)],
    3: [("turn", 0, None, 3.0), ("turn_move", 0, 2, 1.5), ("move", 2, None, 0.7), ("sweep", -1, "flex", 0.5),
        ("curl", -1, None, 0.5)],
    4: [("turn", 1, None, 3.0), ("turn_move", 1, 0, 1.5), ("move", 0, None, 0.5), ("sweep", -1, "thumb", 1.0)],
    5: [("turn", 2, None, 3.0), ("turn_move", 2, 0, 1.5), ("sweep", -1, "spread", 1.0), ("sweep", -1, "thumb", 0.7),
        ("move", 0, None, 0.5)],
}


@dataclass(frozen=True)
class Gesture:
    """What a user does for one motion (dimension, sign)."""

    kind: str  # move | point | turn | turn_move | sweep | curl
    axis: int  # move/point: translation axis; turn/turn_move: rotation axis; -1 for finger gestures
    sign: int  # direction along/about the axis, or which stroke is fast (sweep), curl (+1) / uncurl (-1)
    move_axis: int = -1  # turn_move: translation axis
    pattern: str = ""  # sweep: flex | spread | thumb

    def describe(self) -> str:
        s = "+" if self.sign > 0 else "-"
        xyz = "XYZ"
        if self.kind == "move":
            return f"move hand {s}{xyz[self.axis]}"
        if self.kind == "point":
            return f"point and move {s}{xyz[self.axis]}"
        if self.kind == "turn":
            return f"turn wrist about {s}{xyz[self.axis]}"
        if self.kind == "turn_move":
            return f"turn about {s}{xyz[self.axis]} while moving {s}{xyz[self.move_axis]}"
        if self.kind == "sweep":
            return f"sweep fingers ({self.pattern}, fast stroke {s})"
        return "curl fingers" if self.sign > 0 else "uncurl fingers"


def _claims(kind: str, axis: int, extra) -> set:
    if kind in ("move", "point"):
        return {("trans", axis)}
    if kind == "turn":
        return {("rot", axis)}
    if kind == "turn_move":
        return {("rot", axis), ("trans", extra)}
    if kind == "sweep":
        return {("sweep", extra)}
    return {("curl",)}


@dataclass
class UserProfile:
    """A simulated user: their gestures and the style in which they make them."""

    user_id: str
    group: str
    gestures: dict[tuple[int, int], Gesture]  # (dim, sign) -> gesture
    hand_scale: float
    rest_position: np.ndarray  # (3,) m, wrist at rest in U
    rest_yaw: float  # rad
    speed_m_s: float
    rate_rad_s: float
    repeated: bool
    stroke_freq_hz: float
    stroke_amplitude: float
    curled_posture: bool
    elbow_offset_m: float  # 0 = turns in place about the palm
    relaxed_curl: float
    sweep_amplitude: dict[str, float]
    sweep_freq_hz: float
    curl_rate_per_s: float
    tremor_position_m: float
    tremor_rotation_rad: float
    tremor_freq_hz: np.ndarray  # (3,)
    handler_magnitude: np.ndarray  # (6,) nominal label magnitude per dimension
    mirrored: bool = False

    def describe(self) -> str:
        parts = [f"{DIMENSIONS[d]}+: {self.gestures[(d, 1)].describe()}" for d in range(6)]
        return "; ".join(parts)


def make_user(config: GeneratorConfig, user_id: str, group: str, rng: np.random.Generator) -> UserProfile:
    """Draw a user profile (gestures and style)."""
    u = lambda lo_hi: float(rng.uniform(*lo_hi))  # noqa: E731
    mirrored = bool(rng.random() < config.p_mirrored)
    taken: set = set()
    gestures: dict[tuple[int, int], Gesture] = {}
    for d in rng.permutation(6):
        d = int(d)
        options = [o for o in STRATEGIES[d] if not (_claims(o[0], o[1], o[2]) & taken)]
        if not options:  # every strategy clashes: fall back to the natural one
            options = STRATEGIES[d][:1]
        w = np.array([o[3] for o in options])
        kind, axis, extra, _ = options[int(rng.choice(len(options), p=w / w.sum()))]
        taken |= _claims(kind, axis, extra)
        flip = -1 if rng.random() < config.p_flip_dimension else 1
        if mirrored and d in (0, 1, 3, 4):  # X and Y seen from the robot's side
            flip = -flip
        for s in (1, -1):
            gestures[(d, s)] = Gesture(
                kind=kind,
                axis=axis,
                sign=s * flip,
                move_axis=int(extra) if kind == "turn_move" else -1,
                pattern=str(extra) if kind == "sweep" else "",
            )
    rp = np.array([rng.uniform(*r) for r in config.rest_position_m])
    return UserProfile(
        user_id=user_id,
        group=group,
        gestures=gestures,
        hand_scale=u(config.hand_scale),
        rest_position=rp,
        rest_yaw=float(np.deg2rad(rng.uniform(-config.rest_yaw_deg, config.rest_yaw_deg))),
        speed_m_s=u(config.translation_speed_m_s),
        rate_rad_s=u(config.rotation_rate_rad_s),
        repeated=bool(rng.random() < config.p_repeated_rhythm),
        stroke_freq_hz=u(config.stroke_freq_hz),
        stroke_amplitude=u(config.stroke_amplitude),
        curled_posture=bool(rng.random() < config.p_curled_posture),
        elbow_offset_m=u(config.elbow_offset_m) if rng.random() < config.p_turn_about_elbow else 0.0,
        relaxed_curl=u(config.relaxed_curl),
        sweep_amplitude={
            "flex": u(config.finger_sweep_amplitude),
            "spread": u(config.spread_sweep_amplitude_rad),
            "thumb": u(config.thumb_sweep_amplitude_rad),
        },
        sweep_freq_hz=u(config.finger_sweep_freq_hz),
        curl_rate_per_s=u(config.curl_rate_per_s),
        tremor_position_m=u(config.tremor_position_m),
        tremor_rotation_rad=u(config.tremor_rotation_rad),
        tremor_freq_hz=rng.uniform(*config.tremor_freq_hz, size=3),
        handler_magnitude=np.concatenate(
            [rng.uniform(*config.handler_speed_m_s, size=3), rng.uniform(*config.handler_rate_rad_s, size=3)]
        ),
        mirrored=mirrored,
    )


# --------------------------------------------------------------------------- hand model

# Right hand in its own frame H (reference gesture: palm down, fingers along +Y,
# back of the hand up +Z, thumb toward -X), metres for a scale-1 adult hand.
MCP_POSITIONS = np.array([[-0.026, 0.088, 0.0], [-0.006, 0.090, 0.0], [0.012, 0.084, 0.0], [0.028, 0.074, 0.0]])
PHALANX_LENGTHS = np.array(
    [[0.040, 0.024, 0.020], [0.045, 0.028, 0.021], [0.042, 0.027, 0.021], [0.033, 0.019, 0.018]]
)
FINGER_ABDUCTION_RAD = np.deg2rad([-8.0, 0.0, 6.0, 14.0])  # index..pinky, splayed at rest
THUMB_CMC = np.array([-0.020, 0.028, -0.012])
THUMB_LENGTHS = np.array([0.045, 0.032, 0.027])  # metacarpal, proximal, distal
THUMB_BEND = np.array([0.7071, 0.0, -0.7071])  # thumb flexes toward the pinky side of the palm
PALM_CENTRE = np.array([0.0, 0.05, -0.01])
# Curl level c (0 flat .. 1 fist) to joint angles, per finger joint.
CURL_TO_MCP_RAD = np.deg2rad(85.0)
CURL_TO_PIP_RAD = np.deg2rad(100.0)
CURL_TO_DIP_RAD = np.deg2rad(70.0)
CURL_MIN = -0.15  # slight MCP hyperextension
JOINT_LIMITS_DEG = {"mcp": (-13.0, 85.0), "pip": (0.0, 100.0), "dip": (0.0, 70.0), "abduction": (-25.0, 25.0)}


def hand_keypoints_local(
    curl: np.ndarray, abduction: np.ndarray, thumb: np.ndarray, scale: float
) -> np.ndarray:
    """Keypoints (N, 21, 3) in the hand frame H.

    curl: (N, 4) curl level of index..pinky in [CURL_MIN, 1]; abduction: (N, 4)
    rad added to the rest splay; thumb: (N, 4) = (azimuth from +Y toward the
    thumb side, elevation below the palm, MCP flexion, IP flexion), rad.
    """
    N = curl.shape[0]
    out = np.zeros((N, 21, 3))
    c = np.clip(curl, CURL_MIN, 1.0)
    ab = np.clip(FINGER_ABDUCTION_RAD + abduction, *np.deg2rad(JOINT_LIMITS_DEG["abduction"]))
    phi1 = c * CURL_TO_MCP_RAD
    phi2 = phi1 + np.maximum(c, 0.0) * CURL_TO_PIP_RAD
    phi3 = phi2 + np.maximum(c, 0.0) * CURL_TO_DIP_RAD
    u0 = np.stack([np.sin(ab), np.cos(ab), np.zeros_like(ab)], axis=-1)  # (N, 4, 3)
    down = np.array([0.0, 0.0, -1.0])
    pos = np.broadcast_to(MCP_POSITIONS * scale, (N, 4, 3)).copy()
    base_idx = np.array([5, 9, 13, 17])
    out[:, base_idx] = pos
    for j, phi in enumerate((phi1, phi2, phi3)):
        d = np.cos(phi)[..., None] * u0 + np.sin(phi)[..., None] * down
        pos = pos + d * (PHALANX_LENGTHS[:, j] * scale)[None, :, None]
        out[:, base_idx + j + 1] = pos
    az, el, tm, ti = thumb.T
    u = np.stack([-np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), -np.sin(el)], axis=-1)
    q = THUMB_BEND - np.sum(u * THUMB_BEND, axis=-1, keepdims=True) * u
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    p = np.broadcast_to(THUMB_CMC * scale, (N, 3)).copy()
    out[:, 1] = p
    p = p + u * THUMB_LENGTHS[0] * scale
    out[:, 2] = p
    for j, ang in enumerate((tm, tm + ti)):
        d = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * q
        p = p + d * THUMB_LENGTHS[j + 1] * scale
        out[:, 3 + j] = p
    return out


def rotation_matrices(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors (N, 3) -> matrices (N, 3, 3)."""
    th = np.linalg.norm(rotvec, axis=-1)
    k = rotvec / np.where(th > 1e-12, th, 1.0)[:, None]
    K = np.zeros(rotvec.shape[:-1] + (3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(th)[:, None, None], np.cos(th)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _envelope(t: np.ndarray, on: float, ramp_up: float, off: float, ramp_down: float) -> np.ndarray:
    return _smoothstep((t - on) / ramp_up) * (1.0 - _smoothstep((t - off) / ramp_down))


def _stroke(phase: np.ndarray) -> np.ndarray:
    """Zero-mean, asymmetric periodic waveform (peak about 1)."""
    return (np.sin(phase) + 0.35 * np.sin(2.0 * phase)) / 1.2


def _sawtooth(phase: np.ndarray) -> np.ndarray:
    """Smooth sawtooth: slow rise, fast fall (its negative: slow fall, fast rise)."""
    return (np.sin(phase) - 0.4 * np.sin(2.0 * phase) + 0.15 * np.sin(3.0 * phase)) / 1.2


def _saturate(x: np.ndarray, limit: float) -> np.ndarray:
    """Identity well inside +-limit, bending smoothly to +-limit (a joint or arm at its range)."""
    knee = 0.9 * limit
    over = np.abs(x) - knee
    bent = knee + (limit - knee) * np.tanh(np.maximum(over, 0.0) / (limit - knee))
    return np.where(over > 0.0, np.sign(x) * bent, x)


# --------------------------------------------------------------------------- gestures to hand motion

THUMB_REST_RAD = np.deg2rad([40.0, 20.0, 15.0, 10.0])  # thumb (azimuth, elevation, MCP, IP), relaxed
THUMB_CURLED_RAD = np.deg2rad([25.0, 45.0, 50.0, 40.0])  # tucked in, with the fingers curled or pointing


def gesture_envelope(t: np.ndarray, on: float, ramp_up: float, off: float, ramp_down: float) -> np.ndarray:
    """A gesture's activation at times ``t``: smooth ramp up from ``on``, down from ``off`` (``np.inf``: not yet)."""
    return _envelope(t, on, ramp_up, off, ramp_down)


def stroke_profile(user: UserProfile, envelope: np.ndarray, t: np.ndarray, phase0: float) -> np.ndarray:
    """Speed profile of a move or turn (relative to full speed): steady, or the user's repeated strokes."""
    if user.repeated:
        return envelope * (1.0 + user.stroke_amplitude * _stroke(2 * np.pi * user.stroke_freq_hz * t + phase0))
    return envelope


def relaxed_curl(user: UserProfile) -> np.ndarray:
    """Curl levels (4,) of index..pinky in the user's reference gesture (relaxed, slightly curled)."""
    return user.relaxed_curl + np.array([0.0, 0.02, 0.04, 0.07])


def hand_articulation(
    config: GeneratorConfig,
    user: UserProfile,
    motions: tuple[tuple[int, int], ...],
    envelopes: list[np.ndarray],
    drifts: list[np.ndarray],
    speeds: list[float],
    rates: list[float],
    t: np.ndarray,
    intensity: float,
    phase0: float,
    onset_s: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[tuple[int, np.ndarray]]]:
    """The user's gestures for ``motions`` as finger joints and wrist motion at times ``t`` (N,).

    Per motion k: ``envelopes[k]`` (N,) its activation (0 rest .. 1 full), ``drifts[k]``
    (N,) seconds of full-speed motion so far, ``speeds[k]`` (m/s) and ``rates[k]``
    (rad/s) its hand speed and wrist rate. ``phase0`` (rad) is the phase of the
    strokes and sweeps; ``onset_s`` when the gesture starts (an uncurl first closes
    the hand from there). Every output is pointwise in time given these inputs.

    Returns curl (N, 4), abduction (N, 4) rad, thumb (N, 4) rad (see
    :func:`hand_keypoints_local`), translation (N, 3) m of the wrist in U, and the
    wrist turns [(axis of U, angle (N,) rad)].
    """
    N = t.size
    a_max = np.max(envelopes, axis=0)
    # Finger posture: relaxed at rest, the user's posture while gesturing.
    relaxed = relaxed_curl(user)
    posture = 0.75 if user.curled_posture else 0.02
    curl = relaxed[None, :] + (posture - relaxed)[None, :] * a_max[:, None]
    abduction = np.zeros((N, 4))
    thumb_rest = THUMB_REST_RAD
    thumb_curled = THUMB_CURLED_RAD
    thumb_pose = thumb_rest + (thumb_curled - thumb_rest) * (a_max[:, None] if user.curled_posture else np.zeros((N, 1)))

    translation = np.zeros((N, 3))
    turn_angles: list[tuple[int, np.ndarray]] = []
    for k, (dim, sign) in enumerate(motions):
        g = user.gestures[(dim, sign)]
        a = envelopes[k]
        drift, speed, rate = drifts[k], speeds[k], rates[k]
        if g.kind in ("move", "point"):
            translation[:, g.axis] += g.sign * _saturate(speed * drift, config.max_excursion_m)
            if g.kind == "point":
                point = np.array([0.0, 0.95, 0.95, 0.95])
                curl = curl + (point - curl) * a[:, None]
                thumb_pose = thumb_pose + (thumb_curled - thumb_pose) * a[:, None]
        elif g.kind in ("turn", "turn_move"):
            theta = g.sign * _saturate(rate * drift, config.max_turn_rad)
            turn_angles.append((g.axis, theta))
            if g.kind == "turn_move":
                translation[:, g.move_axis] += g.sign * _saturate(
                    0.7 * speed * drift, config.max_excursion_m
                )
        elif g.kind == "sweep":
            phase = 2 * np.pi * user.sweep_freq_hz * np.sqrt(intensity) * t + phase0
            wave = g.sign * a * _sawtooth(phase) * user.sweep_amplitude[g.pattern] * min(intensity, 1.3)
            if g.pattern == "flex":
                curl = curl + (0.25 - curl) * a[:, None] + wave[:, None]
            elif g.pattern == "spread":
                abduction = abduction + wave[:, None]
            else:
                thumb_pose = thumb_pose + np.stack([wave, 0.3 * wave, 0.5 * np.abs(wave), 0.8 * np.abs(wave)], -1)
        elif g.kind == "curl":
            prog = user.curl_rate_per_s * intensity * drift
            if g.sign > 0:
                curl = curl + (0.05 - curl) * a[:, None] + prog[:, None]
            else:
                pre = _smoothstep((t - onset_s) / 0.3)
                curl = curl + (0.95 - curl) * pre[:, None] - prog[:, None]

    thumb_pose = np.clip(thumb_pose, np.deg2rad([0.0, 0.0, 0.0, -10.0]), np.deg2rad([80.0, 60.0, 60.0, 80.0]))
    return curl, abduction, thumb_pose, translation, turn_angles


def rest_rotation(user: UserProfile) -> np.ndarray:
    """Orientation (3, 3) of the hand frame H in U in the user's reference gesture."""
    return rotation_matrices(np.array([[0.0, 0.0, user.rest_yaw]]))[0]


def hand_pivot(user: UserProfile) -> np.ndarray:
    """Point (3,) of H the wrist turns about: the palm centre, or the elbow behind the wrist."""
    return PALM_CENTRE * user.hand_scale if user.elbow_offset_m == 0.0 else np.array([0.0, -user.elbow_offset_m, 0.0])


def place_hand(user: UserProfile, local: np.ndarray, R: np.ndarray, *offsets: np.ndarray) -> np.ndarray:
    """Keypoints (N, 21, 3) in U of a hand posed as ``local`` (N, 21, 3) in H and turned to ``R`` (N, 3, 3).

    The turn is about :func:`hand_pivot`; the wrist starts at the user's rest
    position and is displaced by each of ``offsets`` ((N, 3) m, added in order).
    """
    wrist = user.rest_position
    for offset in offsets:
        wrist = wrist + offset
    pivot = hand_pivot(user)
    wrist = wrist + (rest_rotation(user) @ pivot) - R @ pivot
    return wrist[:, None, :] + np.einsum("nij,nkj->nki", R, local)


# --------------------------------------------------------------------------- one clip


@dataclass
class ClipTruth:
    """Noise-free quantities of a simulated clip (for tests and plots)."""

    keypoints_clean: np.ndarray  # (N, 21, 3) before jitter and dropout
    intent: np.ndarray  # (N, 6) the handler's target before delay and smoothing
    envelope: np.ndarray  # (N,) activation of the gesture(s)


def simulate_clip(
    config: GeneratorConfig,
    user: UserProfile,
    motions: tuple[tuple[int, int], ...],
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, ClipTruth]:
    """One clip: keypoints (N, 21, 3) with camera effects, object velocity (N, 6), object pose (N, 7)."""
    fps = config.fps
    duration = float(rng.uniform(*config.clip_duration_s))
    N = int(np.floor(duration * fps + 1e-9))
    t = np.arange(N) / fps
    dt = 1.0 / fps
    on = float(rng.uniform(*config.onset_s))
    up = float(rng.uniform(*config.ramp_s))
    down = float(rng.uniform(*config.ramp_s))
    off = N / fps - float(rng.uniform(*config.tail_s)) - down
    intensity = float(np.exp(rng.normal(0.0, config.intensity_log_sd)))

    envs = []
    for k in range(len(motions)):
        shift = 0.0 if k == 0 else float(rng.uniform(-1, 1) * config.second_onset_jitter_s)
        envs.append(_envelope(t, max(on + shift, 0.2), up, off + shift, down))
    a_max = np.max(envs, axis=0)

    phase0 = float(rng.uniform(0, 2 * np.pi))
    drifts, speeds, rates = [], [], []
    for k in range(len(motions)):
        a = envs[k]
        drifts.append(np.cumsum(stroke_profile(user, a, t, phase0)) * dt)  # seconds of full-speed motion so far
        # A person paces a steady move or turn to stay within reach over the whole gesture.
        total = max(float(np.sum(a)) * dt, 1e-3)
        speeds.append(min(user.speed_m_s * intensity, 0.85 * config.max_excursion_m / total))
        rates.append(min(user.rate_rad_s * intensity, 0.85 * config.max_turn_rad / total))
    curl, abduction, thumb_pose, translation, turn_angles = hand_articulation(
        config, user, motions, envs, drifts, speeds, rates, t, intensity, phase0, on)

    local = hand_keypoints_local(curl, abduction, thumb_pose, user.hand_scale)

    # Wrist rotation: the turns' angular velocities about axes of U add up (a person
    # turning "about X and about Z" at once), integrated from the rest pose.
    R_rest = rest_rotation(user)
    omega = np.zeros((N, 3))
    for axis, theta in turn_angles:
        omega[:, axis] += np.gradient(theta, dt) if N > 1 else 0.0
    q = integrate_pose(np.zeros(3), np.hstack([np.zeros((N, 3)), omega]), dt)[:, 3:]
    R = quat_to_matrix(q) @ R_rest
    tremor_phase = rng.uniform(0, 2 * np.pi, size=(2, 3))
    tremor_rot = user.tremor_rotation_rad * np.sin(2 * np.pi * user.tremor_freq_hz * t[:, None] + tremor_phase[0])
    R = rotation_matrices(tremor_rot) @ R

    # Pivot (hand_pivot): turning in place keeps the palm centre still; about the elbow, the elbow.
    wander = config.wander_position_m * np.sin(2 * np.pi * rng.uniform(0.2, 0.5, 3) * t[:, None] + rng.uniform(0, 6.3, 3))
    tremor_pos = user.tremor_position_m * np.sin(2 * np.pi * user.tremor_freq_hz * t[:, None] + tremor_phase[1])
    clean = place_hand(user, local, R, translation, wander, tremor_pos)

    # Camera: jitter and lost frames.
    keypoints = clean + rng.normal(0.0, config.jitter_m, size=clean.shape)
    lost = rng.random(N) < config.dropout_prob
    for start in np.flatnonzero(rng.random(N) < config.burst_prob):
        lost[start : start + int(rng.integers(config.burst_frames[0], config.burst_frames[1] + 1))] = True
    keypoints[lost] = np.nan

    velocity, intent = handler_labels(config, user, motions, envs, intensity, t, rng)
    pose = integrate_pose(np.asarray(config.object_start_position_m), velocity, dt)
    return (
        keypoints.astype(np.float32),
        velocity.astype(np.float32),
        pose.astype(np.float32),
        ClipTruth(keypoints_clean=clean, intent=intent, envelope=a_max),
    )


def handler_labels(
    config: GeneratorConfig,
    user: UserProfile,
    motions: tuple[tuple[int, int], ...],
    envelopes: list[np.ndarray],
    intensity: float,
    t: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Object velocity (N, 6) a handler produces for the gesture, and their intent (N, 6)."""
    N = t.size
    dt = float(t[1] - t[0]) if N > 1 else 1.0 / config.fps
    delay = float(rng.uniform(*config.handler_delay_s))
    lag = float(rng.uniform(*config.handler_lag_s))
    intent = np.zeros((N, 6))
    for (dim, sign), env in zip(motions, envelopes):
        magnitude = (
            user.handler_magnitude[dim]
            * intensity**config.handler_follow_exponent
            * float(np.exp(rng.normal(0.0, config.handler_misjudge_log_sd)))
        )
        intent[:, dim] += sign * magnitude * env
    delayed = np.zeros_like(intent)
    for dim in range(6):
        delayed[:, dim] = np.interp(t - delay, t, intent[:, dim], left=0.0)
    # First-order lag as a causal convolution with an exponential kernel.
    tk = np.arange(int(np.ceil(6 * lag / dt)) + 1) * dt
    kernel = np.exp(-tk / lag)
    kernel /= kernel.sum()
    smooth = np.stack([np.convolve(delayed[:, d], kernel)[:N] for d in range(6)], axis=1)
    active = sorted({d for d, _ in motions})
    leak = np.zeros((6, 6))
    for d in active:
        for j in range(6):
            if j not in active:
                leak[d, j] = rng.normal(0.0, config.handler_crosstalk) * user.handler_magnitude[j] / user.handler_magnitude[d]
    smooth = smooth + smooth @ leak
    noise_sd = np.array([config.tracking_noise_m_s] * 3 + [config.tracking_noise_rad_s] * 3)
    noise = rng.normal(0.0, 1.0, size=(N, 6)) * noise_sd
    noise = 0.5 * (noise + np.vstack([noise[:1], noise[:-1]]))  # marker filter: a little smoothing
    return smooth + noise, intent


def integrate_pose(start: np.ndarray, velocity: np.ndarray, dt: float) -> np.ndarray:
    """Poses (N, 7) [x y z qw qx qy qz] from a start position and twists in U (identity start rotation).

    The angular velocity is spatial (expressed in U), so each step left-multiplies
    the orientation: q_{k+1} = exp(w_k dt / 2) q_k, computed as a parallel prefix product.
    """
    N = velocity.shape[0]
    pos = start + np.vstack([np.zeros((1, 3)), np.cumsum(velocity[:-1, :3], axis=0) * dt])
    half = 0.5 * velocity[:-1, 3:] * dt
    th = np.linalg.norm(half, axis=1)
    dq = np.concatenate([np.cos(th)[:, None], np.sinc(th / np.pi)[:, None] * half], axis=1)
    q = np.vstack([[1.0, 0.0, 0.0, 0.0], dq])  # q[k] = step into frame k
    off = 1
    while off < N:
        q[off:] = quat_multiply(q[off:], q[:-off])
        off *= 2
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.hstack([pos, q])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions [w x y z] (..., 4)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternion arrays [w x y z] (..., 4)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


# --------------------------------------------------------------------------- population


def motion_name(motions: tuple[tuple[int, int], ...]) -> str:
    return "".join(f"{DIMENSIONS[d]}{'+' if s > 0 else '-'}" for d, s in motions)


def user_groups(n_users: int, config: GeneratorConfig) -> list[str]:
    """Group of each user: the first round(fraction * n) are in-sample (10 of 15)."""
    n_in = int(round(config.in_sample_fraction * n_users))
    if n_users >= 1:
        n_in = max(n_in, 1)
    return ["in-sample" if i < n_in else "out-sample" for i in range(n_users)]


def simulate_user(
    config: GeneratorConfig, user_index: int, group: str, seed: int
) -> tuple[UserProfile, list[Clip], list[ClipTruth]]:
    """A user's profile and 72 clips; deterministic in (seed, user_index)."""
    rng = np.random.default_rng([int(seed), int(user_index)])
    user = make_user(config, f"u{user_index:02d}", group, rng)
    clips: list[Clip] = []
    truths: list[ClipTruth] = []
    for i, (motions, split) in enumerate(clip_design(rng, group == "in-sample")):
        kp, vel, pose, truth = simulate_clip(config, user, motions, rng)
        desc = "; ".join(f"{motion_name((m,))}: {user.gestures[m].describe()}" for m in motions)
        clips.append(
            Clip(
                user=user.user_id,
                clip_id=f"{i:02d}_{motion_name(motions)}",
                group=group,
                split=split,
                active_dims=np.array(sorted(d for d, _ in motions), dtype=np.int64),
                fps=config.fps,
                keypoints=kp,
                object_velocity=vel,
                object_pose=pose,
                description=desc,
            )
        )
        truths.append(truth)
    return user, clips, truths


def generate_population(
    config: GeneratorConfig | None = None,
    n_users: int = 15,
    seed: int = 0,
    progress: Callable[[int, int, UserProfile], None] | None = None,
) -> list[Clip]:
    """All clips of ``n_users`` simulated users."""
    config = config or GeneratorConfig()
    clips: list[Clip] = []
    for i, group in enumerate(user_groups(n_users, config)):
        user, user_clips, _ = simulate_user(config, i, group, seed)
        clips.extend(user_clips)
        if progress is not None:
            progress(i + 1, n_users, user)
    return clips


# --------------------------------------------------------------------------- does the population need context?


def _windows(features: np.ndarray, width: int) -> np.ndarray:
    """Rows [window, |window|, window * |window|, 1] for every step t, window = x(t-w+1) .. x(t).

    |x| sees oscillating gestures, x |x| their asymmetry (which stroke is fast).
    The window is zero-padded at the start.
    """
    T = features.shape[0]
    padded = np.vstack([np.zeros((width - 1, features.shape[1]), features.dtype), features])
    win = np.stack([padded[k : k + T] for k in range(width)], axis=1).reshape(T, -1)
    return np.hstack([win, np.abs(win), win * np.abs(win), np.ones((T, 1))])


def _ridge(X: np.ndarray, Y: np.ndarray, alpha: float) -> np.ndarray:
    A = X.T @ X + alpha * np.eye(X.shape[1])
    A[-1, -1] -= alpha  # no penalty on the bias
    return np.linalg.solve(A, X.T @ Y)


def context_need_ratio(policy_clips, width: int = 10, alpha: float = 100.0) -> dict:
    """Test MSE of one context-free ridge regressor for all users over per-user regressors.

    Both regress labels on windows of ``width`` feature steps (and their
    absolute values); both are fitted on in-sample "train" clips and tested on
    in-sample "test" clips. A ratio well above 1 means the same gesture means
    different things for different users, so a policy needs the user's context.
    """
    train = [c for c in policy_clips if c.group == "in-sample" and c.split == "train" and c.labels is not None]
    test = [c for c in policy_clips if c.group == "in-sample" and c.split == "test" and c.labels is not None]
    users = sorted({c.user for c in train})

    def stack(clips):
        X = np.vstack([_windows(c.features.astype(np.float64), width) for c in clips])
        Y = np.vstack([c.labels.astype(np.float64) for c in clips])
        return X, Y

    Xtr, Ytr = stack(train)
    Xte, Yte = stack(test)
    # Standardise the inputs (not the bias) with the pooled training statistics.
    scale = Xtr.std(axis=0)
    scale[scale < 1e-9] = 1.0
    scale[-1] = 1.0
    Xtr, Xte = Xtr / scale, Xte / scale
    W = _ridge(Xtr, Ytr, alpha)
    pooled = float(np.mean((Xte @ W - Yte) ** 2))
    se, n = 0.0, 0
    for u in users:
        Xu, Yu = stack([c for c in train if c.user == u])
        Xv, Yv = stack([c for c in test if c.user == u])
        Xu, Xv = Xu / scale, Xv / scale
        Wu = _ridge(Xu, Yu, alpha)
        se += float(np.sum((Xv @ Wu - Yv) ** 2))
        n += Yv.size
    per_user = se / n
    zero = float(np.mean(Yte**2))
    return {"pooled_mse": pooled, "per_user_mse": per_user, "ratio": pooled / per_user, "zero_mse": zero}
