"""The rest release and the jump guard: the hand's rest and its jumps read as no motion.

A policy's memory outlasts the gesture: the recurrent state, and in a file that reads the hand's
path and shape, 1.6 s of path. When a person stops gesturing and rests their hand, the read can
go on commanding the last gesture for a second or more (docs/policy.md, the rest release). The
rest release scales the policy's output by a gate g in [0, 1] that falls to zero once the hand
has been still for a few policy steps, and returns to 1 the step the hand moves again:

    motion m(t) = sqrt(mean_j (x_j(t) / s_j)^2)       x the 36 hand-part velocities; s_j LINEAR_M_S
                                                       for a linear one, ANGULAR_RAD_S for an angular
                                                       one (fixed: a part's velocity that is only
                                                       tracking jitter must not count as motion)
    still(t)    = m(t) < theta;  n(t) = n(t-1) + 1 if still(t) else 0
    g(t)        = 1 for n <= STILL_FROM, 0 for n >= STILL_TO, linear between

Fitted to each person from their own labelled clips (`fit_rest_release`):
- theta = max(REST_RATIO x the REST_QUANTILE of m over the context's rest steps (no label of
  QUIET of the person's size within REST_MARGIN steps), f x the median m over its commanding steps):
  above the person's own tracking jitter at rest, and below how they move when they gesture;
- f is the largest of MOTION_FLOORS with which the release, run over the person's own clips, takes
  at most HARM of their labels' squared size away: as high as their own gestures allow, so that a
  resting hand whose jitter or drifting the context does not show (an imported recording whose rest
  is held exactly still) still reads as rest;
- it is on only if even the smallest floor keeps within HARM: a person who commands with a still
  hand (a held posture, or labels that outlast the motion) keeps the policy's output as it is;
- labels known to follow the gesture by a lag (a recorder session's cue labels, placed the protocol's
  `label_lag_s` after the gesture to match the lag the policy learned) are moved back onto the gesture
  for the fit (`label_lag_steps`), so that their lag alone does not turn the release off.

The gate only ever scales the command down; it reads the 36 features the policy reads, so a lost
hand (zeros) counts as still. Everything it remembers is the still count n.

The jump guard: a step whose motion m(t) is over JUMP_RATIO x the largest m of the person's own
context steps, with the palm faster than JUMP_SPEED_M_S, is a jump of the tracked hand, not a gesture (the hand re-found elsewhere, another
hand taken for it, a replay moving on to its next recording): its 36 features read as no motion
and a path-and-shape read starts its path afresh there. So does a hand seen again after being
lost for LOST_STEPS policy steps or more: it may be anywhere by then (`guard_stream` offline; the
policy box step by step).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

FEATURES = 36  # the paper's hand-part velocities: the gate reads these, whatever else a file reads
# The motion's scales: a part moving at 0.1 m/s counts as much as one turning at 1 rad/s (the
# simulated handler's nominal speed and turn rate are 0.12 m/s and 0.6 rad/s).
LINEAR_M_S, ANGULAR_RAD_S = 0.1, 1.0
SCALES = np.where((np.arange(FEATURES) % 6) < 3, LINEAR_M_S, ANGULAR_RAD_S)
# Chosen on development people: recorded (SHREC'17 training subjects 2, 4, 8, 10, 12, 14) and a
# simulated development population (generator seed 0) (docs/policy.md, the rest release).
STILL_FROM, STILL_TO = 1, 3  # policy steps still: the gate starts to fall after 1, is 0 after 3 (0.3 s at 10 Hz)
REST_QUANTILE, REST_RATIO = 0.95, 1.5
# The floors tried, largest first (a share of the person's median motion while commanding). Chosen on
# the recorded development people in the closed loop (docs/real_people.md, section 8); 0.1 alone before.
MOTION_FLOORS = (0.5, 0.4, 0.3, 0.2, 0.1)
REST_MARGIN = 2  # policy steps from any label for a step to count as rest
QUIET = 0.05  # a label under this share of the person's size on every axis is no label (tracking noise)
COMMANDING = 0.2  # a label commands when it is at least this share of the person's size on that axis
HARM = 0.05  # the share of the labels' squared size the gate may take away on the person's own clips
# A jump: over this many times the largest motion of the person's context steps (development people:
# recorded context steps reach m = 3-7, the jumps between simulated recordings 11-24, their motion
# 3-5), with the palm faster than this (recorded development people: 99.9 % of their policy steps
# move the hand's centre less than 0.155 m, 1.55 m/s).
JUMP_RATIO = 3.0
JUMP_SPEED_M_S = 1.5
LOST_STEPS = 2  # a hand lost this many policy steps starts a fresh path when it is seen again


@dataclass
class RestRelease:
    """A person's rest release (module docstring). `on` False: the gate is always 1."""

    theta: float = 0.0
    on: bool = False
    still_from: int = STILL_FROM
    still_to: int = STILL_TO
    harm: float = 0.0  # the share of the labels' squared size it takes away on the person's clips
    floor: float = 0.0  # f, the floor theta was fitted with (module docstring)
    jump: float = float("inf")  # m over this is a jump (module docstring)

    def motion(self, x: np.ndarray) -> float:
        x = np.nan_to_num(np.asarray(x, np.float64).reshape(-1)[:FEATURES])
        return float(np.sqrt(np.mean((x / SCALES) ** 2)))

    def is_jump(self, x: np.ndarray) -> bool:
        x = np.nan_to_num(np.asarray(x, np.float64).reshape(-1)[:FEATURES])
        return float(np.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2)) > JUMP_SPEED_M_S and self.motion(x) > self.jump

    def next_count(self, count: float, x: np.ndarray) -> float:
        """The still count n(t) from n(t-1) and x(t)."""
        return count + 1.0 if self.motion(x) < self.theta else 0.0

    def gate(self, count: float) -> float:
        """g for a still count n (1 when off)."""
        if not self.on:
            return 1.0
        return float(np.clip((self.still_to - count) / (self.still_to - self.still_from), 0.0, 1.0))

    def gates(self, features: np.ndarray) -> np.ndarray:
        """(T,) g over a stream of features (T, >= 36), from a still count of 0: step by step what
        `next_count` and `gate` give, in one pass over the array."""
        return self.gates_of_motion(motions(features))

    def gates_of_motion(self, m: np.ndarray) -> np.ndarray:
        """(T,) g over a stream whose steps' motions (`motions`) are m, from a still count of 0."""
        m = np.asarray(m, np.float64).reshape(-1)
        if not self.on:
            return np.ones(len(m))
        still = m < self.theta
        steps = np.arange(len(m))
        # n(t): the steps since the last one that moved (t + 1 when none has yet), 0 on a moving step.
        moved = np.maximum.accumulate(np.where(still, -1, steps)) if len(m) else steps
        n = np.where(still, steps - moved, 0).astype(np.float64)
        return np.clip((self.still_to - n) / (self.still_to - self.still_from), 0.0, 1.0)


def motions(features: np.ndarray) -> np.ndarray:
    """(T,) `RestRelease.motion` of each step of features (T, >= 36)."""
    x = np.asarray(features, np.float64)
    x = np.nan_to_num((x if x.ndim == 2 else x.reshape(len(x), -1))[:, :FEATURES])
    return np.sqrt(np.mean((x / SCALES) ** 2, axis=1))


def release_advice(release: RestRelease) -> str | None:
    """None when the rest release is on; else one line saying why it is off for this person's clips
    and what that means (the run and the reading check print it for a real hand)."""
    if release.on:
        return None
    if release.harm > HARM:
        return (f"the rest release is off for these clips: on them, letting go once the hand is still would take "
                f"{100 * release.harm:.0f} % of the commands (at most {100 * HARM:.0f} % is allowed), because the hand "
                "moves between gestures as much as in them, or the labels go on while it is held still; the "
                "command may then go on for a moment after a gesture ends. Record the clips with the hand still "
                "before each cue and after each gesture")
    return ("the rest release is off for these clips: they show no rest between gestures, or no command; the "
            "command may go on for a moment after a gesture ends")


def _near_label(commanding: np.ndarray, margin: int) -> np.ndarray:
    """(T,) bool: a commanding step within `margin` steps."""
    near = commanding.copy()
    for s in range(1, margin + 1):
        near[s:] |= commanding[:-s]
        near[:-s] |= commanding[s:]
    return near


def fit_rest_release(pieces: Sequence[tuple[np.ndarray, np.ndarray]], label_lag_steps: int = 0) -> RestRelease:
    """A person's rest release from their labelled context pieces [(features (T, >= 36), labels (T, 6))].

    `label_lag_steps`: how many policy steps the labels are known to follow the gesture (a recorder
    session's cue labels, placed later to match the lag the policy learned: `label_lag_s` of the file's
    protocol). The release is fitted with the labels moved that much earlier, back onto the gesture:
    otherwise each label outlasts the still hand by the lag, the release takes the label's tail, and it
    turns itself off for every such person. In the run it then lets go once the hand has been still
    for a moment, before the lagged command's tail ends."""
    lag = max(int(label_lag_steps), 0)

    def aligned(y: np.ndarray) -> np.ndarray:
        return np.vstack([y[lag:], np.zeros((min(lag, len(y)), y.shape[1]))]) if lag else y

    pieces = [(np.nan_to_num(np.asarray(f, np.float64)[:, :FEATURES]),
               aligned(np.nan_to_num(np.asarray(y, np.float64))))
              for f, y in pieces if y is not None and len(f) > 0]
    if not pieces:
        return RestRelease()
    y = np.concatenate([l for _, l in pieces])
    sizes = np.abs(y).max(0)
    piece_motions = [motions(f) for f, _ in pieces]
    release = RestRelease(jump=float(JUMP_RATIO * max(m.max() for m in piece_motions)))
    scaled = np.where(sizes > 0, np.abs(y) / np.where(sizes > 0, sizes, 1.0), 0.0)
    rest, moving = [], []
    for m, (_, l) in zip(piece_motions, pieces):
        on = (np.abs(l) / np.where(sizes > 0, sizes, 1.0)).max(1) >= COMMANDING
        labelled = (np.abs(l) / np.where(sizes > 0, sizes, 1.0)).max(1) >= QUIET
        rest.append(m[~_near_label(labelled, REST_MARGIN)])
        moving.append(m[on])
    rest, moving = np.concatenate(rest), np.concatenate(moving)
    if rest.size == 0 or moving.size == 0 or not scaled.any():
        return release
    jitter = REST_RATIO * np.quantile(rest, REST_QUANTILE)
    for floor in MOTION_FLOORS:  # the largest floor the person's own clips allow (module docstring)
        release.floor = floor
        release.theta = float(max(jitter, floor * np.median(moving)))
        release.on = True
        taken = sum(float((((1.0 - release.gates_of_motion(m)) ** 2)[:, None] * l ** 2).sum())
                    for m, (_, l) in zip(piece_motions, pieces))
        release.harm = taken / max(float((y ** 2).sum()), 1e-12)
        release.on = release.harm <= HARM
        if release.on:
            break
    return release


def guard_stream(release: RestRelease, features: np.ndarray, keypoints: np.ndarray | None = None,
                 rate_hz: float = 10.0) -> np.ndarray:
    """Features (T, 36) of a stream with its jumps read as no motion, as the policy box reads them;
    with `keypoints` (T, 21, 3) at the policy times (NaN when lost), the hand's path and shape
    appended, its path started afresh at each jump."""
    from rtcohand_drake.data.hand_features import PathShapeStream

    x = np.array(features[:, :FEATURES], np.float64)
    stream = PathShapeStream(rate_hz) if keypoints is not None else None
    shapes, lost = [], 0
    for t in range(len(x)):
        jumped = release.is_jump(x[t])
        if jumped:
            x[t] = 0.0
        if stream is not None:
            seen = bool(np.isfinite(keypoints[t]).all())
            if jumped or (seen and lost >= LOST_STEPS):
                stream.reset()
            lost = 0 if seen else lost + 1
            shapes.append(stream.update(keypoints[t])[0])
    return np.hstack([x, np.array(shapes)]) if stream is not None else x
