"""The full diagram with the policy: real-time factor, and gesture-to-command onset latency.

    python benchmarks/bench_diagram.py [--repeats 3] [--duration 30] [--clips 12] [--model PATH.pt] [--onset-only]
        [--plot OUT.png [--compare-model OTHER.pt]] [--scenario S] [--read-lead K] [--responsive-window N]

1. Real-time factor: the built-in simulated person -> shipped CCHP policy ->
   filter -> safety -> diff IK -> simulated Gen3, headless, as fast as possible;
   median simulated-seconds per wall-second over the repeats.
2. Onset latency, in the paper's mode (2 Hz mean of 10 predictions) and in the
   responsive mode, measured in one run of the same clips: single-dimension
   clips of an out-sample user are replayed (context: that user's other
   clips); the gesture starts at the first policy sample whose hand features
   exceed 10% of the clip's peak; the onset is the first supervisor command on
   the clip's active dimension, with the clip's sign, above 20% of that
   command's peak during the clip. Median over the clips, and the ratio.
   Beside it: when the labels themselves (the handler's reaction and lag)
   pass 20% of their peak, and when the policy's output passes the command's
   20% level; command onset minus that is the filter's own lag.
   The mold exit corridor is switched off for this measurement: the part
   starts seated in the mold, where the corridor passes nothing but a lift,
   so with it on only lifting clips would give a command at all.

`--read-lead K` loads the policy file with its `label_lead` set to K (the
read solved for each context label K steps on; the decoder as trained), and
`--responsive-window N` sets the responsive filter's window: probes of what
a file and the filter can give, not settings of the shipped scenario.
"""

from __future__ import annotations

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
from rtcohand_drake.systems.gestures.replay import ReplayGestureSource
from rtcohand_drake.cell.robot_files import models_dir
from rtcohand_drake.repo_paths import repo_relative
from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person
from rtcohand_drake.learning.policy_file import load_policy, reads_path_shape
from rtcohand_drake.systems.policy import CchpPolicy
from rtcohand_drake.scenario import load_scenario


def real_time_factor(scenario, model, duration, repeats):
    factors = []
    for seed in range(repeats):
        source, pieces = make_builtin_person(scenario, seed=seed, path_shape=reads_path_shape(model))
        policy = CchpPolicy.from_scenario(model, pieces, scenario.policy, seed=seed)
        run = build_run_diagram(scenario, source=source, policy=policy)
        simulator = Simulator(run.diagram)
        simulator.Initialize()
        start = time.perf_counter()
        simulator.AdvanceTo(duration)
        factors.append(duration / (time.perf_counter() - start))
    return factors


def _onset(t: np.ndarray, along: np.ndarray, t0: float, level: float | None = None) -> float | None:
    """First time at or after t0 where `along` exceeds `level` (default: 20 % of its own peak); None if never."""
    if along.max() <= 1e-6:
        return None
    level = 0.2 * along.max() if level is None else level
    above = np.flatnonzero((along > level) & (t >= t0 - 1e-9))
    return float(t[above[0]] - t0) if len(above) else None


def onset_latencies(scenario, model, clips, pieces, mode, traces=None):
    """Per clip, after the gesture start (s; None where absent): the label's and the command's onset
    (each above 20 % of its own peak), and the policy output's onset above the command's level
    (20 % of the command's peak), so that command - policy is the filter's own lag. If `traces` is a
    list, each clip's signals along its active dimension (with the clip's sign) are appended to it."""
    scenario.command_filter.mode = mode
    scenario.safety.mold_exit_height_m = 0.0  # the corridor off (module docstring)
    rate = scenario.policy.rate_hz
    onsets = []
    for clip in clips:
        policy = CchpPolicy.from_scenario(model, pieces, scenario.policy)
        source = ReplayGestureSource([clip], rate)
        run = build_run_diagram(scenario, source=source, policy=policy)
        simulator = Simulator(run.diagram)
        simulator.AdvanceTo(source.end_time)
        root = simulator.get_context()
        # A log sample at time t holds the state before that time's update: the value the
        # system set one of its periods earlier. Times below are when each value was set.
        log = run.loggers["command_twist"].FindLog(root)
        t, cmd = log.sample_times() - scenario.safety.period_s, log.data().T
        plog = run.loggers["policy_mean"].FindLog(root)
        tp, mean = plog.sample_times() - 1.0 / rate, plog.data().T
        dim = int(clip.active_dims[0])
        sign = np.sign(clip.labels[np.argmax(np.abs(clip.labels[:, dim])), dim])
        strength = np.linalg.norm(clip.features, axis=1)
        t0 = int(np.argmax(strength > 0.1 * strength.max())) / rate
        t_label = np.arange(len(clip.labels)) / rate
        along = sign * cmd[:, dim]
        level = 0.2 * along.max() if along.max() > 1e-6 else None
        if traces is not None:
            traces.append({"t0": t0, "features": (t_label, strength / strength.max()),
                           "labels": (t_label, sign * clip.labels[:, dim]), "policy": (tp, sign * mean[:, dim]),
                           "command": (t, along), "dim": dim})
        onsets.append((_onset(t_label, sign * clip.labels[:, dim], t0),
                       _onset(tp, sign * mean[:, dim], t0, level) if level is not None else None,
                       _onset(t, along, t0)))
    return onsets


def plot_traces(path: Path, runs: dict, clips: int = 4) -> None:
    """The first `clips` clips: features, labels, policy output and command of each run, from the gesture's start."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
    first = next(iter(runs.values()))
    n = min(clips, len(first))
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.2), sharey=True, squeeze=False)
    for i, ax in enumerate(axes[0]):
        ref = first[i]
        t0 = ref["t0"]
        peak = max(ref["labels"][1].max(), 1e-9)
        tf, f = ref["features"]
        ax.plot(tf - t0, f, color="0.7", lw=1, label="hand features (share of peak)")
        tl, yl = ref["labels"]
        ax.plot(tl - t0, yl / peak, color="k", lw=2, label="labels (handler)")
        for (name, traces), color in zip(runs.items(), ("tab:blue", "tab:orange", "tab:green", "tab:red")):
            tc, c = traces[i]["command"]
            ax.plot(tc - t0, c / peak, color=color, lw=1.5, label=f"command, {name}")
            if not name.startswith("paper"):  # the same policy output as the responsive run's
                tp, m = traces[i]["policy"]
                ax.plot(tp - t0, m / peak, color=color, lw=1, ls=":", label=f"policy output, {name}")
        ax.axvline(0.0, color="0.5", lw=0.8)
        ax.axhline(0.2, color="0.5", lw=0.8, ls="--")
        ax.set_xlim(-0.5, 3.0)
        ax.set_title(f"clip {i + 1}: {names[ref['dim']]}")
        ax.set_xlabel("time from the gesture's start (s)")
    axes[0][0].set_ylabel("along the clip's motion, share of the label's peak")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _median_ms(values) -> str:
    values = [v for v in values if v is not None]
    return f"{statistics.median(values) * 1e3:.0f} ms ({len(values)} clips)" if values else "n/a"


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--clips", type=int, default=12)
    p.add_argument("--model", type=Path, default=None, help="a policy file (default: the scenario's)")
    p.add_argument("--onset-only", action="store_true", help="skip the real-time factor")
    p.add_argument("--plot", type=Path, default=None, help="save the first clips' traces (PNG)")
    p.add_argument("--compare-model", type=Path, default=None,
                   help="with --plot: also draw this policy file's responsive command")
    p.add_argument("--scenario", default="inspection", help="built-in scenario name or YAML path")
    p.add_argument("--read-lead", type=int, default=None, help="override the file's label_lead (a probe)")
    p.add_argument("--responsive-window", type=int, default=None, help="the responsive filter's window (a probe)")
    args = p.parse_args()
    scenario = load_scenario(args.scenario)
    model = args.model if args.model is not None else models_dir() / scenario.policy.model
    print(f"policy: {repo_relative(model)}")  # its output is kept in docs/results
    if args.responsive_window is not None:
        scenario.command_filter.responsive_window = args.responsive_window
        print(f"responsive window: {args.responsive_window}")
    if args.read_lead is not None:
        model = load_policy(model)
        model.label_lead = args.read_lead
        print(f"read's lead: {args.read_lead} steps")

    if not args.onset_only:
        factors = real_time_factor(scenario, model, args.duration, args.repeats)
        print(f"full diagram with policy: real-time factor median {statistics.median(factors):.1f}x "
              f"(min {min(factors):.1f}x, {args.repeats} runs of {args.duration:.0f} s)")

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "population.h5"
        write_dataset(path, generate_population(GeneratorConfig(), n_users=15, seed=0))
        clips = load_policy_clips(path)
        # The context as the policy file reads it (with the hand's path and shape for a file that reads them);
        # the replayed clips give the source its 36 features.
        context_clips = load_policy_clips(path, path_shape=True) if reads_path_shape(model) else clips
    user = sorted({c.user for c in clips if c.group == "out-sample"})[0]
    mine = [i for i, c in enumerate(clips) if c.user == user]
    chosen = [i for i in mine if len(clips[i].active_dims) == 1][: args.clips]
    singles = [clips[i] for i in chosen]
    pieces = [(context_clips[i].features, context_clips[i].labels) for i in mine if i not in chosen]
    traces = {"paper": [], "responsive": []}
    paper = onset_latencies(scenario, model, singles, pieces, "paper", traces["paper"])
    responsive = onset_latencies(scenario, model, singles, pieces, "responsive", traces["responsive"])
    commands = {name: [o[2] for o in onsets] for name, onsets in (("paper", paper), ("responsive", responsive))}
    mp = statistics.median([v for v in commands["paper"] if v is not None])
    mr = statistics.median([v for v in commands["responsive"] if v is not None])
    print(f"onset latency (user {user}, {len(singles)} single-dimension clips), gesture start -> 20 % of peak:")
    print(f"  labels (the handler's reaction and lag): {_median_ms([o[0] for o in paper])}")
    for name, onsets in (("paper", paper), ("responsive", responsive)):
        print(f"  policy output above the {name} command's 20 % level: {_median_ms([o[1] for o in onsets])}")
    for name, onsets in (("paper", paper), ("responsive", responsive)):
        lag = [c - p for _, p, c in onsets if c is not None and p is not None]
        print(f"  command, {name} mode: {_median_ms(commands[name])}; the filter's own lag "
              f"(command onset - policy onset, per clip): {_median_ms(lag)}")
    print(f"  ratio of command onsets, paper / responsive: {mp / mr:.1f}x")
    if args.plot is not None:
        runs = {"responsive": traces["responsive"], "paper": traces["paper"]}
        if args.compare_model is not None:
            other: list = []
            compared = onset_latencies(scenario, args.compare_model, singles, pieces, "responsive", other)
            runs[f"responsive, {args.compare_model.name}"] = other
            print(f"  command, responsive mode, {args.compare_model}: {_median_ms([o[2] for o in compared])}")
        plot_traces(args.plot, runs)
        print(f"wrote {args.plot}")

if __name__ == "__main__":
    main()
