"""The operator's controls: pause/resume and sensitivity.

Output port (both systems)
  operator (2) [pause (0/1), sensitivity factor]

- `MeshcatOperatorPanel`: a Meshcat button "Pause / Resume" (also the space
  bar) toggles the pause; a Meshcat slider sets the sensitivity. It polls
  Meshcat every `period_s` into discrete state.
- `ScheduledOperatorPanel`: pauses during given intervals, at a fixed sensitivity;
  for headless runs and tests.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.systems.safety.config import Safety
from rtcohand_drake.interfaces import OPERATOR, OPERATOR_DIM

PAUSE_BUTTON = "Pause / Resume (space)"
SENSITIVITY_SLIDER = "Sensitivity"


class MeshcatOperatorPanel(LeafSystem):
    def __init__(self, meshcat, safety: Safety, period_s: float = 0.05):
        super().__init__()
        self._meshcat = meshcat
        meshcat.AddButton(PAUSE_BUTTON, "Space")
        meshcat.AddSlider(SENSITIVITY_SLIDER, safety.sensitivity_min, safety.sensitivity_max, 0.05,
                          safety.sensitivity_default)
        self._state = self.DeclareDiscreteState(np.array([0.0, safety.sensitivity_default, 0.0]))
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._poll)
        self.DeclareVectorOutputPort(OPERATOR, OPERATOR_DIM, self._calc, prerequisites_of_calc={self.xd_ticket()})

    def _poll(self, context, discrete_state):
        paused, _, clicks_seen = context.get_discrete_state(self._state).get_value()
        clicks = self._meshcat.GetButtonClicks(PAUSE_BUTTON)
        if (clicks - clicks_seen) % 2 == 1:
            paused = 1.0 - paused
        sensitivity = self._meshcat.GetSliderValue(SENSITIVITY_SLIDER)
        discrete_state.set_value(self._state, [paused, sensitivity, clicks])

    def _calc(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).get_value()[:2])

    def remove(self) -> None:
        self._meshcat.DeleteButton(PAUSE_BUTTON)
        self._meshcat.DeleteSlider(SENSITIVITY_SLIDER)


class ScheduledOperatorPanel(LeafSystem):
    def __init__(self, pauses: Sequence[tuple[float, float]] = (), sensitivity: float = 1.0):
        super().__init__()
        self._pauses = [(float(a), float(b)) for a, b in pauses]
        self._sensitivity = float(sensitivity)
        self.DeclareVectorOutputPort(OPERATOR, OPERATOR_DIM, self._calc)

    def _calc(self, context, output: BasicVector):
        t = context.get_time()
        paused = any(a <= t < b for a, b in self._pauses)
        output.SetFromVector([1.0 if paused else 0.0, self._sensitivity])
