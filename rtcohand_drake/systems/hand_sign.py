"""`PauseHandSign`: a thumbs-up, held still for `hand_sign.hold_s`, toggles the pause.

It sits between the operator panel and the safety supervisor and toggles the
very pause the panel's button toggles: the supervisor sees
`pause = panel pause XOR sign toggled`, so a thumbs-up pauses, a thumbs-up (or the
button) resumes, and the Meshcat lamp turns amber either way. The sign is
a thumbs-up rather than a plain fist because a fist is one of the gestures
people use for motions (the simulated population's "curl fingers"); none
of them points the thumb up.

The sign (`rtcohand_drake.systems.hand_sign_config.HandSign`): the four
fingers closed, openness = mean fingertip distance from the wrist / mean
knuckle (MCP) distance from the wrist (scale free) below `fist_below`, and
the thumb (MCP to tip) within `thumb_up_within_deg` of up (+Z of U), and the
fist on its side: the hand's axis (wrist to the middle knuckle) at least
`axis_from_up_min_deg` from up (a hand held upright as it closes points its
thumb up too). The hand makes the sign from then until openness rises above
`open_above`, the thumb leaves `thumb_up_within_deg` + `thumb_hysteresis_deg`
or the axis comes within `axis_from_up_min_deg` - `thumb_hysteresis_deg` of
up (hysteresis). It
must be held still, every point within `max_drift_m` of where it was when
the hold began, for `hold_s` without a break (a lost hand breaks it). After a toggle the sign
must end before the next one: a held thumbs-up toggles once. No hand of the
simulated population makes the sign in any of its gestures
(tests/test_hand_sign.py).

Input ports
  keypoints  (63) the hand skeleton, metres, user frame (NaN when lost)
  operator   (2)  [pause (0/1), sensitivity] from the operator panel
Output ports
  operator   (2)  [pause (0/1), sensitivity] to the supervisor
  hand_sign  (3)  [toggled (0/1), openness (NaN when no hand), toggles so far]
Updates every `period_s` (discrete state).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.interfaces import HAND_SIGN, HAND_SIGN_DIM, KEYPOINTS, KEYPOINTS_DIM, OPERATOR, OPERATOR_DIM
from rtcohand_drake.systems.hand_sign_config import HandSign

TIPS, KNUCKLES, WRIST, MIDDLE_KNUCKLE = [8, 12, 16, 20], [5, 9, 13, 17], 0, 9
# State: toggled, sign (0/1), armed (0/1), hold start (s, NaN: none), toggles, openness, the
# skeleton (63) when the hold began.
_TOGGLED, _SIGN, _ARMED, _HOLD, _COUNT, _OPEN, _KP = 0, 1, 2, 3, 4, 5, slice(6, 69)
STATE_SIZE = 69


def openness(keypoints: np.ndarray) -> float:
    """Mean fingertip-to-wrist over mean knuckle-to-wrist distance; NaN for a lost hand."""
    kp = np.asarray(keypoints, float).reshape(21, 3)
    if not np.all(np.isfinite(kp)):
        return float("nan")
    tips = np.linalg.norm(kp[TIPS] - kp[WRIST], axis=1).mean()
    knuckles = np.linalg.norm(kp[KNUCKLES] - kp[WRIST], axis=1).mean()
    return float(tips / knuckles) if knuckles > 1e-6 else float("nan")


def _from_up_deg(keypoints: np.ndarray, start: int, end: int) -> float:
    """The angle (deg) from up (+Z of U) of the line from keypoint `start` to keypoint `end`."""
    kp = np.asarray(keypoints, float).reshape(21, 3)
    d = kp[end] - kp[start]
    n = np.linalg.norm(d)
    return float(np.degrees(np.arccos(np.clip(d[2] / n, -1.0, 1.0)))) if n > 1e-9 else float("nan")


def thumb_elevation_deg(keypoints: np.ndarray) -> float:
    """The thumb's (MCP to tip) angle from up (+Z of U), degrees."""
    return _from_up_deg(keypoints, 2, 4)


def axis_from_up_deg(keypoints: np.ndarray) -> float:
    """The hand's axis (wrist to the middle finger's knuckle) angle from up (+Z of U), degrees."""
    return _from_up_deg(keypoints, WRIST, MIDDLE_KNUCKLE)


def initial_state() -> np.ndarray:
    state = np.zeros(STATE_SIZE)
    state[_HOLD] = state[_OPEN] = np.nan
    state[_KP] = np.nan
    return state  # not armed: a hand that starts with the sign must end it first


def sign_step(state: np.ndarray, keypoints: np.ndarray, t: float, config: HandSign) -> np.ndarray:
    """The next state (module docstring) from the skeleton seen at time `t`."""
    s = np.array(state, float)
    kp = np.asarray(keypoints, float).reshape(21, 3)
    o = openness(kp)
    s[_OPEN] = o
    if not np.isfinite(o):  # no hand: the hold breaks, nothing else changes
        s[_HOLD] = np.nan
        return s
    held = s[_SIGN] > 0.5
    slack = config.thumb_hysteresis_deg if held else 0.0
    sign = (o < (config.open_above if held else config.fist_below)
            and thumb_elevation_deg(kp) < config.thumb_up_within_deg + slack
            and axis_from_up_deg(kp) >= config.axis_from_up_min_deg - slack)
    s[_SIGN] = 1.0 if sign else 0.0
    # Held still: every point within `max_drift_m` of where it was when the hold began (this
    # tolerates the tracker's jitter; a gesture moves the hand further).
    if np.isfinite(s[_HOLD]) and np.linalg.norm(kp - s[_KP].reshape(21, 3), axis=1).max() > config.max_drift_m:
        s[_HOLD] = np.nan
    if not sign:
        s[_ARMED], s[_HOLD] = 1.0, np.nan
    elif s[_ARMED] > 0.5:
        if not np.isfinite(s[_HOLD]):
            s[_HOLD], s[_KP] = t, kp.reshape(-1)
        if t - s[_HOLD] >= config.hold_s - 1e-9:
            s[_TOGGLED] = 1.0 - s[_TOGGLED]
            s[_COUNT] += 1
            s[_ARMED], s[_HOLD] = 0.0, np.nan
    return s


class PauseHandSign(LeafSystem):
    def __init__(self, config: HandSign):
        super().__init__()
        self._config = config
        self.period_s = config.period_s
        self._keypoints = self.DeclareVectorInputPort(KEYPOINTS, KEYPOINTS_DIM)
        self._panel = self.DeclareVectorInputPort(OPERATOR, OPERATOR_DIM)
        self._state = self.DeclareDiscreteState(initial_state())
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareVectorOutputPort(OPERATOR, OPERATOR_DIM, self._calc_operator,
                                     prerequisites_of_calc={self.xd_ticket(), self._panel.ticket()})
        self.DeclareVectorOutputPort(HAND_SIGN, HAND_SIGN_DIM, self._calc_sign, prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        state = context.get_discrete_state(self._state).get_value()
        discrete_state.set_value(self._state, sign_step(state, self._keypoints.Eval(context),
                                                        context.get_time(), self._config))

    def _calc_operator(self, context, output: BasicVector):
        pause, sensitivity = self._panel.Eval(context)
        toggled = context.get_discrete_state(self._state).get_value()[_TOGGLED] > 0.5
        output.SetFromVector([1.0 if (pause >= 0.5) != toggled else 0.0, sensitivity])

    def _calc_sign(self, context, output: BasicVector):
        s = context.get_discrete_state(self._state).get_value()
        output.SetFromVector([s[_TOGGLED], s[_OPEN], s[_COUNT]])
