"""Reference policies: what the loop achieves with a policy that reads every gesture right."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.interfaces import GESTURE_FEATURES, INTENDED_TWIST, POLICY_MEAN, POLICY_STD, RESUME_COUNT


class IntentPolicy(LeafSystem):
    """A reference in place of the CCHP policy: the simulated person's intended twist, delayed.

    Not a policy anyone can deploy (a real person's intent is not observable):
    it measures what the rest of the loop (filter, supervisor, IK, arm) achieves
    with a policy that reads every gesture right, `delay_s` late. Same ports as
    `CchpPolicy` plus the input `intended_twist`, which the run diagram wires to
    the simulated person's output of that name.
    """

    def __init__(self, rate_hz: float = 10.0, delay_s: float = 0.3):
        super().__init__()
        period = 1.0 / rate_hz
        self._lag = max(0, int(round(delay_s / period)))
        self.DeclareVectorInputPort(GESTURE_FEATURES, 36)
        self.DeclareVectorInputPort(RESUME_COUNT, 1)
        self._intent = self.DeclareVectorInputPort(INTENDED_TWIST, 6)
        self._buffer = self.DeclareDiscreteState(np.zeros(6 * (self._lag + 1)))  # newest last
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort(POLICY_MEAN, 6, self._calc_mean, prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort(POLICY_STD, 6, lambda context, out: out.SetFromVector(np.zeros(6)))

    def _update(self, context, discrete_state):
        buffer = context.get_discrete_state(self._buffer).get_value()
        intent = np.asarray(self._intent.Eval(context), float)
        discrete_state.set_value(self._buffer, np.concatenate([buffer[6:], np.nan_to_num(intent)]))

    def _calc_mean(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._buffer).get_value()[:6])
