"""Simulated people: the clip design, the gesture strategies, and each user's profile."""

from __future__ import annotations

from typing import TYPE_CHECKING
from dataclasses import dataclass

import numpy as np

from rtcohand_drake.data.dataset import DIMENSIONS

if TYPE_CHECKING:
    from rtcohand_drake.data.population.config import GeneratorConfig

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
    single_stroke: bool = False  # each move or turn is one stroke, out and partly back
    stroke_return: float = 0.0  # single stroke: how far back (0 one way .. 1 all the way)
    stroke_speed_gain: float = 1.0  # single stroke: speed against the user's steady speed

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
    user = UserProfile(
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
    # Drawn last, and only when some users stroke, so a population without them is drawn as before.
    if config.p_single_stroke > 0.0 and rng.random() < config.p_single_stroke:
        user.single_stroke = True
        user.stroke_return = u(config.single_stroke_return)
        user.stroke_speed_gain = u(config.single_stroke_speed_gain)
    # Also drawn last, and only when some users gesture directly, for the same reason.
    if config.p_direct > 0.0 and rng.random() < config.p_direct:
        user.gestures = direct_gestures(user.gestures)
    return user


def direct_gestures(gestures: dict[tuple[int, int], Gesture]) -> dict[tuple[int, int], Gesture]:
    """The same motions made the direct way: dimension d's first strategy (a move along the axis, a turn
    about it), each with the sign the user drew for it."""
    out = {}
    for (d, s), g in gestures.items():
        kind, axis, _, _ = STRATEGIES[d][0]
        flip = g.sign * s  # the sign the user drew for dimension d (mirroring and flips)
        out[(d, s)] = Gesture(kind=kind, axis=axis, sign=s * flip)
    return out


# --------------------------------------------------------------------------- population


def motion_name(motions: tuple[tuple[int, int], ...]) -> str:
    return "".join(f"{DIMENSIONS[d]}{'+' if s > 0 else '-'}" for d, s in motions)


def user_groups(n_users: int, config: GeneratorConfig) -> list[str]:
    """Group of each user: the first round(fraction * n) are in-sample (10 of 15)."""
    n_in = int(round(config.in_sample_fraction * n_users))
    if n_users >= 1:
        n_in = max(n_in, 1)
    return ["in-sample" if i < n_in else "out-sample" for i in range(n_users)]
