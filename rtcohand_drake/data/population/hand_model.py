"""An anatomical right hand: bone lengths, joint ranges, forward kinematics, and how a gesture moves it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from rtcohand_drake.cell.geometry import smoothstep

if TYPE_CHECKING:
    from rtcohand_drake.data.population.config import GeneratorConfig
    from rtcohand_drake.data.population.people import UserProfile

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


def _envelope(t: np.ndarray, on: float, ramp_up: float, off: float, ramp_down: float) -> np.ndarray:
    return smoothstep((t - on) / ramp_up) * (1.0 - smoothstep((t - off) / ramp_down))


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
    """Speed profile of a move or turn (relative to full speed): steady, the user's repeated strokes, or
    one stroke out and back over the gesture.

    One stroke: over the span where the envelope is on, with s its share (0 .. 1) of that span, the
    speed is (1 - r) + 2 r cos(pi s) for the user's return r: the hand goes out, then comes back
    until its net motion is 1 - r of the steady motion's (r = 1: it ends where it began)."""
    if user.single_stroke:
        on = np.flatnonzero(envelope > 1e-3)
        if on.size < 2:
            return envelope
        s = np.clip((t - t[on[0]]) / (t[on[-1]] - t[on[0]]), 0.0, 1.0)
        r = user.stroke_return
        return envelope * ((1.0 - r) + 2.0 * r * np.cos(np.pi * s))
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
                pre = smoothstep((t - onset_s) / 0.3)
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
