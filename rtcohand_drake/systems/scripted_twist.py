"""A scripted twist source: drives the station without a gesture pipeline.

`ScriptedTwist` plays the scenario's `scripted_motion` segments back to back:
each segment holds a constant user-frame twist for its duration, with short
cosine ramps at both ends so the command is continuous. After the last segment
the command is zero.

Output ports
  twist_request  (6) [vx vy vz wx wy wz], m/s and rad/s, user frame
  gesture_status (2) [1, t]: a script is always a fresh, valid command
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc
from typing import Sequence

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.interfaces import GESTURE_STATUS, GESTURE_STATUS_DIM, TWIST_DIM, TWIST_REQUEST


@dc.dataclass
class TwistSegment:
    """A constant commanded twist (user frame) held for a duration."""

    duration_s: float = 1.0
    twist: list[float] = dc.field(default_factory=lambda: [0.0] * 6)


class ScriptedTwist(LeafSystem):
    def __init__(self, segments: Sequence[TwistSegment], ramp_s: float = 0.3):
        super().__init__()
        self._starts = np.cumsum([0.0] + [s.duration_s for s in segments])
        self._twists = np.array([s.twist for s in segments], dtype=float).reshape(-1, 6)
        self._ramp = ramp_s
        self.DeclareVectorOutputPort(TWIST_REQUEST, TWIST_DIM, self._calc)
        self.DeclareVectorOutputPort(GESTURE_STATUS, GESTURE_STATUS_DIM, self._calc_status)

    @property
    def end_time(self) -> float:
        return float(self._starts[-1])

    def twist_at(self, t: float) -> np.ndarray:
        i = int(np.searchsorted(self._starts, t, side="right")) - 1
        if i < 0 or i >= len(self._twists):
            return np.zeros(6)
        t0, t1 = self._starts[i], self._starts[i + 1]
        ramp = min(self._ramp, 0.5 * (t1 - t0))
        edge = min(t - t0, t1 - t)
        gain = 1.0 if edge >= ramp else 0.5 - 0.5 * np.cos(np.pi * edge / ramp)
        return gain * self._twists[i]

    def _calc(self, context, output: BasicVector):
        output.SetFromVector(self.twist_at(context.get_time()))

    def _calc_status(self, context, output: BasicVector):
        output.SetFromVector([1.0, context.get_time()])


def from_options(options, scenario):
    """The `scripted` source: the scenario's `scripted_motion`, no policy."""
    from rtcohand_drake.systems.gestures.registry import GestureSetup

    return GestureSetup(ScriptedTwist(scenario.scripted_motion))
