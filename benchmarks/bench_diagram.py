"""The full diagram with the policy: real-time factor, and gesture-to-command onset latency.

    python benchmarks/bench_diagram.py [--repeats 3] [--duration 30] [--clips 12]

1. Real-time factor: the built-in simulated operator -> shipped CCHP policy ->
   filter -> safety -> diff IK -> simulated Gen3, headless, as fast as possible;
   median simulated-seconds per wall-second over the repeats.
2. Onset latency, in the paper's mode (2 Hz mean of 10 predictions) and in the
   responsive mode, measured in one run of the same clips: single-dimension
   clips of an out-sample user are replayed (context: that user's other
   clips); the gesture starts at the first policy sample whose hand features
   exceed 10% of the clip's peak; the onset is the first supervisor command on
   the clip's active dimension, with the clip's sign, above 20% of that
   command's peak during the clip. Median over the clips, and the ratio.
   The mold exit corridor is switched off for this measurement: the part
   starts seated in the mold, where the corridor passes nothing but a lift,
   so with it on only lifting clips would give a command at all.
"""

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from rtcohand_drake.data.dataset import load_policy_clips, write_dataset
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.gestures import ReplayGestureSource
from rtcohand_drake.model_files import models_dir
from rtcohand_drake.operator_sim import make_builtin_operator
from rtcohand_drake.policy_system import CchpPolicy
from rtcohand_drake.scenario import load_scenario


def real_time_factor(scenario, model, duration, repeats):
    factors = []
    for seed in range(repeats):
        source, pieces = make_builtin_operator(scenario, seed=seed)
        policy = CchpPolicy(model, pieces, scenario.policy.rate_hz, seed=seed)
        run = build_run_diagram(scenario, source=source, policy=policy)
        simulator = Simulator(run.diagram)
        simulator.Initialize()
        start = time.perf_counter()
        simulator.AdvanceTo(duration)
        factors.append(duration / (time.perf_counter() - start))
    return factors


def onset_latencies(scenario, model, clips, pieces, mode):
    scenario.command_filter.mode = mode
    scenario.safety.mold_exit_height_m = 0.0  # the corridor off (module docstring)
    latencies = []
    for clip in clips:
        policy = CchpPolicy(model, pieces, scenario.policy.rate_hz, seed=0)
        source = ReplayGestureSource([clip], scenario.policy.rate_hz)
        run = build_run_diagram(scenario, source=source, policy=policy)
        simulator = Simulator(run.diagram)
        simulator.AdvanceTo(source.end_time)
        log = run.loggers["command_twist"].FindLog(simulator.get_context())
        t, cmd = log.sample_times(), log.data().T
        dim = int(clip.active_dims[0])
        sign = np.sign(clip.labels[np.argmax(np.abs(clip.labels[:, dim])), dim])
        strength = np.linalg.norm(clip.features, axis=1)
        k0 = int(np.argmax(strength > 0.1 * strength.max()))
        along = sign * cmd[:, dim]
        if along.max() <= 1e-6:
            continue  # the policy never commanded this motion: no onset to measure
        above = np.flatnonzero((along > 0.2 * along.max()) & (t >= k0 / scenario.policy.rate_hz))
        if len(above):
            latencies.append(t[above[0]] - k0 / scenario.policy.rate_hz)
    return latencies


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--clips", type=int, default=12)
    args = p.parse_args()
    scenario = load_scenario("inspection")
    model = models_dir() / scenario.policy.model

    factors = real_time_factor(scenario, model, args.duration, args.repeats)
    print(f"full diagram with policy: real-time factor median {statistics.median(factors):.1f}x "
          f"(min {min(factors):.1f}x, {args.repeats} runs of {args.duration:.0f} s)")

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "population.h5"
        write_dataset(path, generate_population(GeneratorConfig(), n_users=15, seed=0))
        clips = load_policy_clips(path)
    user = sorted({c.user for c in clips if c.group == "out-sample"})[0]
    mine = [c for c in clips if c.user == user]
    singles = [c for c in mine if len(c.active_dims) == 1][: args.clips]
    pieces = [(c.features, c.labels) for c in mine if c not in singles]
    paper = onset_latencies(scenario, model, singles, pieces, "paper")
    responsive = onset_latencies(scenario, model, singles, pieces, "responsive")
    mp, mr = statistics.median(paper), statistics.median(responsive)
    print(f"onset latency (user {user}, {len(singles)} single-dimension clips): paper mode median {mp * 1e3:.0f} ms "
          f"({len(paper)} clips), responsive mode median {mr * 1e3:.0f} ms ({len(responsive)} clips), "
          f"ratio {mp / mr:.1f}x")


if __name__ == "__main__":
    main()
