"""`MovingAverageDownsampler`: the policy's 10 Hz predictions -> the commanded twist.

Two modes, chosen in the scenario's `command_filter`:

- `paper`: the deployment of the CCHP paper. Every `command_period_s` (0.5 s,
  i.e. 2 Hz) the command becomes the mean of the last `window` (10)
  predictions, clamped per axis. Smooth, but it lags: a new gesture reaches
  the arm only after up to a command period plus half the window.
- `responsive`: a command at every policy update = the mean of the last
  `responsive_window` (3) predictions, clamped per axis, and changing no
  faster than the linear/angular acceleration limits (a jerk-free ramp).

In both modes the mean passes a per-axis deadband before the clamp: with
d = `deadband[i]`, an axis whose mean x has |x| <= d commands zero, one with
|x| >= 2 d commands x unchanged, and in between x (|x| - d) / d, continuous
in x. A policy's small output while the hand rests, and its small cross-talk
onto axes the person is not using, then leave the part still; a gesture's
command (tenths of m/s and rad/s) passes as it is. All zeros: no deadband.

Input ports
  policy_mean   (6) predicted twist [vx vy vz wx wy wz], user frame; sampled at
                the policy rate, just after each policy update. Non-finite
                predictions count as zero.
  resume_count  (1) optional; when it changes (the operator resumed after a
                pause), the history is cleared so that no stale prediction
                carries over.
Output ports
  twist_request (6) the filtered, downsampled twist, user frame
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc
import numpy as np
from pydrake.systems.framework import LeafSystem

from rtcohand_drake.interfaces import POLICY_MEAN, RESUME_COUNT, SCALAR_DIM, TWIST_DIM, TWIST_REQUEST


@dc.dataclass
class CommandFilter:
    """The moving-average/downsampler between the policy and the safety supervisor."""

    # "paper": a command every command_period_s = mean of the last `window` predictions
    # (the paper's deployment: 2 Hz, 10 predictions). "responsive": a command at every
    # policy update = mean of the last `responsive_window` predictions, rate-limited.
    mode: str = "paper"
    window: int = 10
    command_period_s: float = 0.5
    responsive_window: int = 3
    # Per-axis clamp on the filtered twist [vx vy vz wx wy wz] (m/s, rad/s).
    clamp: list[float] = dc.field(default_factory=lambda: [0.15, 0.15, 0.15, 0.8, 0.8, 0.8])
    # Responsive mode's limit on how fast the command may change (m/s^2, rad/s^2).
    max_linear_accel_m_s2: float = 0.5
    max_angular_accel_rad_s2: float = 3.0
    # Per-axis deadband d [vx vy vz wx wy wz] (m/s, rad/s) on the mean: zero within d, unchanged
    # beyond 2 d, continuous in between (module docstring). Zeros: none.
    deadband: list[float] = dc.field(default_factory=lambda: [0.0] * 6)

def apply_deadband(x: np.ndarray, deadband: np.ndarray) -> np.ndarray:
    """Per axis: 0 where |x| <= d, x where |x| >= 2 d, x (|x| - d) / d between (continuous); d = 0 passes x."""
    x = np.asarray(x, float)
    d = np.asarray(deadband, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(d > 0, np.clip((np.abs(x) - d) / np.where(d > 0, d, 1.0), 0.0, 1.0), 1.0)
    return x * share


# Sample the policy's output this long after its update, so the newest prediction is seen.
SAMPLE_DELAY_S = 1e-3


class MovingAverageDownsampler(LeafSystem):
    def __init__(self, config: CommandFilter, policy_period_s: float):
        super().__init__()
        self._cfg = config
        self._dt = policy_period_s
        self._clamp = np.asarray(config.clamp, float)
        self._deadband = np.asarray(config.deadband, float)
        self._n = config.window if config.mode == "paper" else config.responsive_window
        self._in = self.DeclareVectorInputPort(POLICY_MEAN, TWIST_DIM)
        self._resume = self.DeclareVectorInputPort(RESUME_COUNT, SCALAR_DIM)
        # History ring buffer (n x 6, row-major), number of samples held, next slot.
        self._history = self.DeclareDiscreteState(np.zeros(self._n * 6))
        self._meta = self.DeclareDiscreteState(np.array([0.0, 0.0, 0.0]))  # [count, head, last resume_count]
        self._command = self.DeclareDiscreteState(np.zeros(6))
        self.DeclarePeriodicDiscreteUpdateEvent(policy_period_s, SAMPLE_DELAY_S, self._sample)
        if config.mode == "paper":
            self.DeclarePeriodicDiscreteUpdateEvent(config.command_period_s, 2 * SAMPLE_DELAY_S, self._emit)
        self.DeclareStateOutputPort(TWIST_REQUEST, self._command)

    @property
    def mode(self) -> str:
        return self._cfg.mode

    def _mean(self, history: np.ndarray, count: int) -> np.ndarray:
        """The mean of the held predictions, through the deadband and the clamp."""
        if count == 0:
            return np.zeros(6)
        mean = history.reshape(self._n, 6)[: min(count, self._n)].mean(axis=0)
        return np.clip(apply_deadband(mean, self._deadband), -self._clamp, self._clamp)

    def _sample(self, context, discrete_state):
        history = context.get_discrete_state(self._history).get_value().copy()
        count, head, last_resume = context.get_discrete_state(self._meta).get_value()
        command = context.get_discrete_state(self._command).get_value().copy()
        if self._resume.HasValue(context):
            resume = float(self._resume.Eval(context)[0])
            if resume != last_resume:
                history[:], count, head, last_resume = 0.0, 0, 0, resume
                command[:] = 0.0
        y = self._in.Eval(context)
        y = np.where(np.isfinite(y), y, 0.0)
        history.reshape(self._n, 6)[int(head)] = y
        head = (head + 1) % self._n
        count = min(count + 1, self._n)
        if self._cfg.mode == "responsive":
            target = self._mean(history, int(count))
            step = np.array([self._cfg.max_linear_accel_m_s2] * 3 + [self._cfg.max_angular_accel_rad_s2] * 3) * self._dt
            command = command + np.clip(target - command, -step, step)
        discrete_state.set_value(self._history, history)
        discrete_state.set_value(self._meta, np.array([count, head, last_resume]))
        discrete_state.set_value(self._command, command)

    def _emit(self, context, discrete_state):
        history = context.get_discrete_state(self._history).get_value()
        count = int(context.get_discrete_state(self._meta).get_value()[0])
        discrete_state.set_value(self._command, self._mean(history, count))
