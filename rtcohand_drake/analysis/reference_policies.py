"""Reference policies: what the loop achieves with a policy that reads every gesture right."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.interfaces import (FEATURE_DIM, GESTURE_FEATURES, INTENDED_TWIST, POLICY_MEAN, POLICY_STD,
                                       RESUME_COUNT, SCALAR_DIM, TWIST_DIM)


class IntentPolicy(LeafSystem):
    """A reference in place of the CCHP policy: the simulated (or recorded) person's intended twist, delayed.

    Not a policy anyone can deploy (a real person's intent is not observable):
    it measures what the rest of the loop (filter, supervisor, IK, arm) achieves
    with a policy that reads every gesture right, `delay_s` late. Same ports as
    `CchpPolicy` plus the input `intended_twist`, which the run diagram wires to
    the source's output of that name (a recorded person's: the label of the frame it plays).
    """

    def __init__(self, rate_hz: float = 10.0, delay_s: float = 0.3):
        super().__init__()
        period = 1.0 / rate_hz
        self._lag = max(0, int(round(delay_s / period)))
        self.DeclareVectorInputPort(GESTURE_FEATURES, FEATURE_DIM)
        self.DeclareVectorInputPort(RESUME_COUNT, SCALAR_DIM)
        self._intent = self.DeclareVectorInputPort(INTENDED_TWIST, TWIST_DIM)
        self._buffer = self.DeclareDiscreteState(np.zeros(6 * (self._lag + 1)))  # newest last
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort(POLICY_MEAN, TWIST_DIM, self._calc_mean, prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort(POLICY_STD, TWIST_DIM, lambda context, out: out.SetFromVector(np.zeros(6)))

    def _update(self, context, discrete_state):
        buffer = context.get_discrete_state(self._buffer).get_value()
        intent = np.asarray(self._intent.Eval(context), float)
        discrete_state.set_value(self._buffer, np.concatenate([buffer[6:], np.nan_to_num(intent)]))

    def _calc_mean(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._buffer).get_value()[:6])


def run_intent_reference(scenario, user: str, *, seed: int = 0, population_seed: int = 0, delay_s: float = 0.3,
                         duration_s: float | None = None, stop_when_done: bool = False):
    """The inspection with `IntentPolicy` in place of CCHP, for the built-in simulated person `user`
    of population `population_seed`: the scored run log (`diagram.collect_run_log`). It runs for
    `duration_s` (default: the scenario's cap), or, with `stop_when_done`, until the scenario's hold
    after the sixth face, as the run command does."""
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person

    source, _ = make_builtin_person(scenario, seed=seed, user=user, population_seed=population_seed)
    return run_intent_with_source(scenario, source, seed=seed, delay_s=delay_s, duration_s=duration_s,
                                  stop_when_done=stop_when_done)


def run_intent_with_source(scenario, source, *, seed: int = 0, delay_s: float = 0.3, duration_s: float | None = None,
                           stop_when_done: bool = False, gesture_source: str = "intent"):
    """`run_intent_reference` for any source with an `intended_twist` output (a simulated or
    recorded person): the scored run log."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.analysis.inspection import score_run_log
    from rtcohand_drake.diagram import build_run_diagram, collect_run_log
    from rtcohand_drake.systems.inspection_monitor import until_done

    run = build_run_diagram(scenario, source=source, policy=IntentPolicy(scenario.policy.rate_hz, delay_s),
                            gesture_source=gesture_source)
    simulator = Simulator(run.diagram)
    if stop_when_done:
        simulator.set_monitor(until_done(run.monitor, scenario.done_hold_s))
    simulator.AdvanceTo(scenario.duration_s if duration_s is None else duration_s)
    log = collect_run_log(run, simulator.get_context(), scenario)
    score_run_log(log, scenario)
    log.extra_attrs.update(seed=seed, sim_duration_s=simulator.get_context().get_time())
    return log
