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

The parts: `config` (every number), `people` (strategies and profiles),
`hand_model` (the anatomical hand), `handler` (the labels); this module
simulates clips, users and whole populations from them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rtcohand_drake.cell.geometry import quaternion_to_matrix
from rtcohand_drake.data.dataset import Clip
from rtcohand_drake.data.population.config import DEFAULT_SEED, DEFAULT_USERS, GeneratorConfig
from rtcohand_drake.data.population.hand_model import (
    JOINT_LIMITS_DEG,
    THUMB_REST_RAD,
    _envelope,
    gesture_envelope,
    hand_articulation,
    hand_keypoints_local,
    hand_pivot,
    place_hand,
    relaxed_curl,
    rest_rotation,
    rotation_matrices,
    stroke_profile,
)
from rtcohand_drake.data.population.handler import handler_labels, integrate_pose, quat_multiply
from rtcohand_drake.data.population.people import (
    STRATEGIES,
    Gesture,
    UserProfile,
    clip_design,
    make_user,
    motion_name,
    user_groups,
)


__all__ = [
    "ClipTruth",
    "DEFAULT_SEED",
    "DEFAULT_USERS",
    "GeneratorConfig",
    "Gesture",
    "JOINT_LIMITS_DEG",
    "STRATEGIES",
    "THUMB_REST_RAD",
    "UserProfile",
    "clip_design",
    "context_need_ratio",
    "generate_population",
    "gesture_envelope",
    "hand_articulation",
    "hand_keypoints_local",
    "hand_pivot",
    "handler_labels",
    "integrate_pose",
    "make_user",
    "motion_name",
    "place_hand",
    "quat_multiply",
    "relaxed_curl",
    "rest_rotation",
    "rotation_matrices",
    "simulate_clip",
    "simulate_user",
    "stroke_profile",
    "user_groups",
]


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
    if user.single_stroke:  # one short stroke: the gesture lasts the stroke's duration, then rest
        off = min(off, on + float(rng.uniform(*config.single_stroke_s)) - down)
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
        gain = user.stroke_speed_gain  # 1 unless the user strokes
        speeds.append(min(gain * user.speed_m_s * intensity, 0.85 * config.max_excursion_m / total))
        rates.append(min(gain * user.rate_rad_s * intensity, 0.85 * config.max_turn_rad / total))
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
    R = quaternion_to_matrix(q, normalize=False) @ R_rest
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
    if config.glitch_prob > 0.0:  # drawn last, so a population without glitches is drawn as before
        add_tracking_glitches(keypoints, config, rng)
    pose = integrate_pose(np.asarray(config.object_start_position_m), velocity, dt)
    return (
        keypoints.astype(np.float32),
        velocity.astype(np.float32),
        pose.astype(np.float32),
        ClipTruth(keypoints_clean=clean, intent=intent, envelope=a_max),
    )


def add_tracking_glitches(keypoints: np.ndarray, config: GeneratorConfig, rng: np.random.Generator) -> None:
    """Shifts `keypoints` (N, 21, 3) in place over the frames where the tracker glitches
    (`GeneratorConfig.glitch_*`): the whole hand by one vector of a log-uniform size in a random
    direction, and each keypoint by its own share of that size."""
    N = len(keypoints)
    lo, hi = config.glitch_m
    for start in np.flatnonzero(rng.random(N) < config.glitch_prob):
        frames = slice(start, start + int(rng.integers(config.glitch_frames[0], config.glitch_frames[1] + 1)))
        size = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        direction = rng.normal(size=3)
        direction /= max(np.linalg.norm(direction), 1e-12)
        own = rng.normal(0.0, config.glitch_keypoint_share * size / np.sqrt(3), size=keypoints.shape[1:])
        keypoints[frames] += size * direction + own


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
