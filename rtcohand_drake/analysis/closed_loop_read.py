"""How the policy reads a simulated person in the closed-loop task, against what that person means.

The open-loop measures (`context_reading`, `evaluate`) score the policy on
recorded clips. In the task, the built-in simulated person gestures in
response to where the part is, and the run is as fast as the policy's output
follows the person's intended twist. `measure` runs the inspection with a
policy box in the loop and samples, every policy period, the person's
intended twist a(t) (`SimulatedPerson`'s `intended_twist`, zero between
gestures) and the policy's output m(t). From those:

- **lag**: the shift k (policy periods) that maximises the output explained
  by the intent, sum over axes of (a_d . m_d,k)^2 / (a_d . a_d), where m_d,k
  is m_d delayed by k; k in 0 .. max_lag;
- **gain** of each axis the person used: the least-squares g in m_d,k = g a_d
  at that lag (1 = the person's own speed; the axes the person never used
  are NaN);
- **rest output**: the mean |v| and |w| of the output one lag after the
  person intended nothing (the hand at rest or away);
- **still command**: the supervisor's command once the person has
  intended nothing for `still_s` (1 s: longer than any lag of the loop), when
  the part should stay where it is: its mean |v| and |w|, and the share of
  those samples in which it commands any motion (|v| > 1 mm/s or |w| > 0.01
  rad/s);
- **completion**: when the sixth face counted (None if it never did).

`IntentPolicy` (the intended twist delayed) in the same loop reads with gain
1 at its own delay, which is what the test checks.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from rtcohand_drake.interfaces import INTENDED_TWIST, POLICY_MEAN, TWIST_COMMAND

AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


@dc.dataclass
class ClosedLoopRead:
    user: str
    population_seed: int
    seed: int
    completion_s: float | None
    lag_s: float
    gains: list[float]          # per axis; NaN where the person never used the axis
    rest_v_m_s: float
    rest_w_rad_s: float
    duration_s: float
    # The supervisor's command once the person has intended nothing for `still_s` (the part
    # should be still): the mean |v| and |w|, and the share of those samples with any motion.
    still_v_m_s: float = float("nan")
    still_w_rad_s: float = float("nan")
    still_moving_share: float = float("nan")


def read_figures(intent: np.ndarray, output: np.ndarray, period_s: float, max_lag: int = 8,
                 used_fraction: float = 0.05) -> tuple[float, list[float], float, float]:
    """(lag s, per-axis gains, rest |v|, rest |w|) of `output` (T, 6) against `intent` (T, 6), both
    sampled every `period_s`. An axis counts as used when its largest |intent| is at least
    `used_fraction` of the largest over all axes of its kind (linear or angular)."""
    intent = np.nan_to_num(np.asarray(intent, float))
    output = np.asarray(output, float)
    n = len(intent)
    if n < max_lag + 2:
        raise ValueError(f"need more than {max_lag + 1} samples, got {n}")

    def explained(k: int) -> float:
        a, m = intent[: n - k], output[k:]
        energy = (a * a).sum(axis=0)
        return float(np.sum(np.where(energy > 0, (a * m).sum(axis=0) ** 2 / np.maximum(energy, 1e-300), 0.0)))

    k = max(range(max_lag + 1), key=explained)
    a, m = intent[: n - k], output[k:]
    peak = np.abs(intent).max(axis=0)
    kind_peak = np.concatenate([np.full(3, peak[:3].max()), np.full(3, peak[3:].max())])
    used = (peak > 0) & (peak >= used_fraction * kind_peak)
    gains = [float((a[:, d] @ m[:, d]) / (a[:, d] @ a[:, d])) if used[d] else float("nan") for d in range(6)]
    rest = ~np.any(a != 0.0, axis=1)  # the person intended nothing one lag earlier
    rest_v = float(np.linalg.norm(m[rest, :3], axis=1).mean()) if rest.any() else float("nan")
    rest_w = float(np.linalg.norm(m[rest, 3:], axis=1).mean()) if rest.any() else float("nan")
    return k * period_s, gains, rest_v, rest_w


def still_figures(intent: np.ndarray, command: np.ndarray, period_s: float, still_s: float = 1.0):
    """(mean |v|, mean |w|, share moving) of `command` (T, 6) at the samples where `intent` (T, 6) has
    been zero for the last `still_s`; NaNs if there are none."""
    idle = ~np.any(np.nan_to_num(np.asarray(intent, float)) != 0.0, axis=1)
    k = max(1, int(round(still_s / period_s)))
    run = np.convolve(idle.astype(float), np.ones(k), mode="full")[: len(idle)]
    still = run >= k - 0.5
    if not still.any():
        return float("nan"), float("nan"), float("nan")
    v = np.linalg.norm(np.asarray(command, float)[still, :3], axis=1)
    w = np.linalg.norm(np.asarray(command, float)[still, 3:], axis=1)
    return float(v.mean()), float(w.mean()), float(np.mean((v > 1e-3) | (w > 1e-2)))


def measure_person(scenario, user: str, population_seed: int, seed: int = 0, intent_delay_s: float | None = None,
                   duration_s: float | None = None, generator=None) -> ClosedLoopRead:
    """`measure` as one task of a sweep (`analysis.engine.run_tasks`): the intent reference with
    `intent_delay_s`, else the scenario's policy; only picklable arguments."""
    from rtcohand_drake.analysis.reference_policies import IntentPolicy

    policy = None if intent_delay_s is None else IntentPolicy(scenario.policy.rate_hz, intent_delay_s)
    return measure(scenario, user, population_seed, seed, policy=policy, duration_s=duration_s, generator=generator)


def measure(scenario, user: str, population_seed: int, seed: int = 0, policy=None,
            duration_s: float | None = None, max_lag: int = 8, generator=None) -> ClosedLoopRead:
    """The inspection for the built-in person `user` of population `population_seed` (drawn with the
    `data.population.GeneratorConfig` `generator`; default the generator's defaults), with `policy`
    (default: the scenario's CCHP policy with that person's clips as context), until the scenario's
    hold after the sixth face or `duration_s` (default: the scenario's cap)."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.cell.robot_files import models_dir
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person
    from rtcohand_drake.systems.inspection_monitor import until_done
    from rtcohand_drake.systems.policy import CchpPolicy

    from rtcohand_drake.learning.policy_file import reads_path_shape

    model = models_dir() / scenario.policy.model
    source, pieces = make_builtin_person(scenario, seed=seed, user=user, population_seed=population_seed,
                                         path_shape=policy is None and reads_path_shape(model), generator=generator)
    rate = scenario.policy.rate_hz
    if policy is None:
        policy = CchpPolicy.from_scenario(model, pieces, scenario.policy, seed=seed)
    gesture_source = "intent" if policy.HasInputPort(INTENDED_TWIST) else None
    run = build_run_diagram(scenario, source=source, policy=policy, gesture_source=gesture_source)
    simulator = Simulator(run.diagram)
    simulator.set_monitor(until_done(run.monitor, scenario.done_hold_s))
    root = simulator.get_context()
    source_context = source.GetMyContextFromRoot(root)
    policy_context = policy.GetMyContextFromRoot(root)
    supervisor = run.diagram.GetSubsystemByName("safety")
    supervisor_context = supervisor.GetMyContextFromRoot(root)
    intent_port, mean_port = source.GetOutputPort(INTENDED_TWIST), policy.GetOutputPort(POLICY_MEAN)
    command_port = supervisor.GetOutputPort(TWIST_COMMAND)
    cap = scenario.duration_s if duration_s is None else duration_s
    period = 1.0 / rate
    intent, output, command = [], [], []
    for step in range(1, int(round(cap * rate)) + 1):
        status = simulator.AdvanceTo(step * period)
        intent.append(np.array(intent_port.Eval(source_context), float))
        output.append(np.array(mean_port.Eval(policy_context), float))
        command.append(np.array(command_port.Eval(supervisor_context), float))
        if status.reason() != status.ReturnReason.kReachedBoundaryTime:
            break
    done_at = run.monitor.inspected_at(run.monitor.GetMyContextFromRoot(root))
    completion = float(done_at.max()) if np.all(np.isfinite(done_at)) else None
    lag, gains, rest_v, rest_w = read_figures(np.array(intent), np.array(output), period, max_lag)
    still = still_figures(np.array(intent), np.array(command), period)
    return ClosedLoopRead(user, population_seed, seed, completion, lag, gains, rest_v, rest_w, root.get_time(), *still)


def from_run_log(path, max_lag: int = 8) -> ClosedLoopRead:
    """The same figures from a run log (`run --log`, a study's logs) of a source that writes the
    intended twist (a simulated or recorded person; for a recorded person, the label of the frame
    played): the policy's output and the supervisor's command sampled at the gesture's samples, up
    to the sixth face or the end of the run. The person is the file's folder and name; the population
    seed the log's `population_seed` attribute, else -1 (not shown)."""
    from pathlib import Path

    from rtcohand_drake.errors import InputError
    from rtcohand_drake.run_log import read_run_log

    log = read_run_log(path)
    n = len(log.gesture_time)
    if n == 0 or len(log.gesture_intended) != n or len(log.policy_time) == 0:
        raise InputError(f"{path}: the run log has no intended twist (a simulated or recorded person's run)")
    end = log.completion_time if log.completed and np.isfinite(log.completion_time) else np.inf
    keep = log.gesture_time <= end + 1e-9
    times = log.gesture_time[keep]
    at = lambda t, x: np.asarray(x, float)[np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 1)]
    intent = np.nan_to_num(np.asarray(log.gesture_intended, float)[keep])
    output = at(log.policy_time, log.policy_mean)
    if len(times) < max_lag + 2:
        raise InputError(f"{path}: the run lasted {len(times)} policy periods, too short to measure")
    command = at(log.command_time, log.command_twist) if len(log.command_time) else np.zeros_like(output)
    period = float(np.median(np.diff(times)))
    lag, gains, rest_v, rest_w = read_figures(intent, output, period, max_lag)
    still = still_figures(intent, command, period)
    return ClosedLoopRead(f"{Path(path).parent.name}/{Path(path).stem}", int(log.extra_attrs.get("population_seed", -1)),
                          int(log.extra_attrs.get("seed", 0)), float(end) if np.isfinite(end) else None, lag, gains,
                          rest_v, rest_w, float(times[-1]), *still)


def markdown(rows: list[ClosedLoopRead]) -> str:
    head = ("| person | completion | lag | " + " | ".join(f"gain {a}" for a in AXES)
            + " | rest output v / w | still command v / w (share moving) |\n|---|---|---|" + "---|" * 6 + "---|---|\n")
    fmt = lambda g: "-" if not np.isfinite(g) else f"{g:+.2f}"
    body = "".join(
        f"| {f'p{r.population_seed}/' if r.population_seed >= 0 else ''}{r.user} | "
        f"{f'{r.completion_s:.1f} s' if r.completion_s is not None else 'not done'} "
        f"| {r.lag_s * 1e3:.0f} ms | " + " | ".join(fmt(g) for g in r.gains)
        + f" | {r.rest_v_m_s:.3f} m/s / {r.rest_w_rad_s:.3f} rad/s | {r.still_v_m_s:.3f} m/s / "
        f"{r.still_w_rad_s:.3f} rad/s ({r.still_moving_share:.0%}) |\n" for r in rows)
    return head + body
