"""The gesture-against-joystick study (`python -m rtcohand_drake.study`), on a distributed engine.

    python -m rtcohand_drake.study [--populations 100-119] [--run-seeds 0 1] [--workers 2 | --address tcp://HOST:8786]
        [--conditions responsive paper joystick intent] [--cap 180] [--out docs/results/study] [--logs DIR]
    python -m rtcohand_drake.study --recorded-people PEOPLE.h5 --out DIR [--people ...]   # analysis.recorded_study

For each out-sample person (u10-u14) of each generated population and each
run seed, the inspection task is run to its end (all six faces plus the
run's short hold, or the cap) in four conditions, under the same cell, IK
and safety layer:

- `responsive`: the person's own gestures, read by the shipped policy with
  their own labelled clips as context, the responsive command filter;
- `paper`: the same with the paper's filter (2 Hz mean of 10 predictions);
- `joystick`: the same person at the arm maker's joystick
  (`rtcohand_drake.systems.joystick`);
- `intent`: the person's intended twist, 0.3 s late, in place of the
  policy (what a perfect reader would get; `analysis.reference_policies`).

A person is a user of a population: their perception delay and decision
rhythm depend on the run seed and on who they are, in every condition, so
a person's four runs are paired.

Each run is one task of `analysis.engine.run_tasks`: on a local Dask
cluster by default, on an existing one with `--address`, or in this process
(`--workers 0`, or without the `distributed` extra). A run goes through the
run command's own code (`rtcohand_drake.run.main`), writes its run log to
`--logs`, and returns its summary. A run that raises is retried once, then
reported with its error (and the command exits 1).

The paper's figure is the per-person ratio of completion times, gesture over
joystick: 1.89 +- 0.66. This writes to `--out` a table per person and run
seed (completion time, faces, median commanded speed while moving), the
paired comparisons with bootstrap 95 % intervals and a paired test
(`analysis.study_stats`), the engine's wall time and throughput, and plots
of the completion times and of the paired times per person.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import contextlib
import io
import json
import re
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.errors import ArgumentParser, InputError, non_negative_int, positive_float, run_cli

CONDITIONS = ("responsive", "paper", "joystick", "intent")
GESTURE_CONDITIONS = ("responsive", "paper")  # the conditions a policy file reads
OUT_SAMPLE = ("u10", "u11", "u12", "u13", "u14")
PAPER_RATIO = (1.89, 0.66)
# The study's "moving" share and median speeds count a command as moving the part when the
# norm of its linear half exceeds 5 mm/s or that of its angular half 0.02 rad/s: a measure of
# the report only, so it stays fixed across scenarios (the filter's deadband, per axis, is a
# scenario key and may change).
MOVING_SPEED_M_S = 0.005
MOVING_TURN_RAD_S = 0.02


def run_condition(population: int, user: str, condition: str, out: str, seed: int = 0,
                  cap_s: float | None = None, model: str | None = None) -> dict:
    """One run, its log written to `out`; returns its summary (`summarise`) with the log's path.

    `cap_s` replaces the scenario's cap (`duration_s`); the run still ends a short hold after
    the sixth face. `model`, a policy file, replaces the scenario's in the gesture conditions
    (the joystick and the intent reference read no gestures). Raises on a run that exits with an
    error."""
    log = Path(out) / log_name(population, user, condition, seed, model)
    log.parent.mkdir(parents=True, exist_ok=True)
    if condition == "intent":
        _run_intent(population, user, log, seed, cap_s)
    else:
        _run_command(population, user, condition, log, seed, cap_s, model)
    return {**summarise(str(log)), "log": str(log)}


def log_name(population: int, user: str, condition: str, seed: int, model: str | None = None) -> str:
    """The run log's file name; a gesture condition read by another policy file than the
    scenario's carries the file's stem, so the runs of two files can share one logs folder."""
    tag = f"_m{Path(model).stem}" if model and condition in GESTURE_CONDITIONS else ""
    return f"p{population}_{user}_{condition}{tag}_s{seed}.h5"


def _run_command(population: int, user: str, condition: str, log: Path, seed: int, cap_s: float | None,
                 model: str | None = None) -> None:
    import tempfile

    import yaml

    from rtcohand_drake.run import main
    from rtcohand_drake.scenario import resolve_scenario_path

    with tempfile.TemporaryDirectory() as folder:
        scenario = "inspection"
        if cap_s is not None:  # a copy of the scenario with its cap changed
            data = yaml.safe_load(resolve_scenario_path(scenario).read_text())
            data["duration_s"] = float(cap_s)
            scenario = str(Path(folder) / "inspection_capped.yaml")
            Path(scenario).write_text(yaml.safe_dump(data, sort_keys=False))
        args = ["--scenario", scenario, "--realtime-rate", "0", "--no-meshcat", "--user", user,
                "--population-seed", str(population), "--seed", str(seed), "--log", str(log)]
        if condition == "joystick":
            args += ["--gesture-source", "joystick"]
        else:
            args += ["--filter-mode", condition] + (["--model", str(model)] if model else [])
        with contextlib.redirect_stdout(io.StringIO()):
            status = main(args)
    if status != 0:
        raise RuntimeError(f"{log.name}: the run exited with status {status}")


def _run_intent(population: int, user: str, log: Path, seed: int, cap_s: float | None) -> None:
    from rtcohand_drake.analysis.reference_policies import run_intent_reference
    from rtcohand_drake.run_log import write_run_log
    from rtcohand_drake.scenario import load_scenario

    write_run_log(log, run_intent_reference(load_scenario("inspection"), user, seed=seed, population_seed=population,
                                            duration_s=cap_s, stop_when_done=True))


def summarise(path: str) -> dict:
    """Completion, faces over time and commanded speed of one run log."""
    from rtcohand_drake.analysis.inspection import measure_inspection
    from rtcohand_drake.cell.plant import eye_position
    from rtcohand_drake.run_log import read_run_log
    from rtcohand_drake.scenario import load_scenario

    log = read_run_log(path)
    result = measure_inspection(log.robot_time, log.robot_workpiece_pose, eye_position(load_scenario("inspection").cell))
    speed = np.linalg.norm(log.command_twist[:, :3], axis=1) if len(log.command_twist) else np.zeros(0)
    turn = np.linalg.norm(log.command_twist[:, 3:], axis=1) if len(log.command_twist) else np.zeros(0)
    moving = (speed > MOVING_SPEED_M_S) | (turn > MOVING_TURN_RAD_S)
    kinds: dict[str, int] = {}
    for e in log.events:
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
    safe = not bool(log.extra_attrs.get("mold_touched", False)) and not bool(log.extra_attrs.get("cell_touched", False))
    return {
        "completed": bool(log.completed and safe),
        "completion_s": float(log.completion_time) if log.completed else None,
        "faces": int(log.faces_inspected),
        "face_times_s": sorted(t for t in result.inspected_at.values() if np.isfinite(t)),
        # Each over the samples where that part of the command moves at all.
        "median_speed_m_s": float(np.median(speed[speed > MOVING_SPEED_M_S])) if (speed > MOVING_SPEED_M_S).any() else 0.0,
        "median_turn_rad_s": float(np.median(turn[turn > MOVING_TURN_RAD_S])) if (turn > MOVING_TURN_RAD_S).any() else 0.0,
        "moving_share": float(moving.mean()) if len(moving) else 0.0,
        "ik_no_solution": kinds.get("ik_no_solution", 0),
    }


# The comparisons the study reports: (condition, baseline).
COMPARISONS = (("responsive", "joystick"), ("paper", "joystick"), ("responsive", "intent"), ("paper", "responsive"),
               ("intent", "joystick"))


def collect(outcomes, conditions: Sequence[str]) -> tuple[dict, list[dict]]:
    """`{person: {condition: {run_seed: summary or None}}}` and the failed runs, from the engine's outcomes."""
    results: dict = {}
    failed = []
    for o in outcomes:
        population, user, condition, seed = o.key
        person = f"p{population}/{user}"
        results.setdefault(person, {c: {} for c in conditions})[condition][seed] = o.value if o.ok else None
        if not o.ok:
            failed.append({"person": person, "condition": condition, "run_seed": seed, "attempts": o.attempts,
                           "error": o.error})
    return results, failed


def comparisons(results: dict, conditions: Sequence[str], cap_s: float, n_boot: int = 10000) -> list:
    from rtcohand_drake.analysis.study_stats import compare

    return [compare(results, a, b, cap_s, n_boot=n_boot) for a, b in COMPARISONS if a in conditions and b in conditions]


def markdown(results: dict, conditions: Sequence[str], cap_s: float, compared: Sequence = (),
             failed: Sequence[dict] = (), engine_line: str = "") -> str:
    """Per person and run seed, the time (faces) and median speeds; then the paired comparisons
    (`comparisons`' result)."""
    lines = ["| person | run seed | " + " | ".join(f"{c}: time (faces), median v / w" for c in conditions) + " |",
             "|---|---|" + "---|" * len(conditions)]
    for person, runs in results.items():
        seeds = sorted({s for c in conditions for s in runs.get(c, {})})
        for seed in seeds:
            cells = []
            for c in conditions:
                r = runs.get(c, {}).get(seed, "missing")
                if r == "missing":
                    cells.append("-")
                elif r is None:
                    cells.append("failed")
                else:
                    time = f"{r['completion_s']:.1f} s" if r["completed"] else "not done"
                    cells.append(f"{time} ({r['faces']}/6), {r['median_speed_m_s']:.3f} m/s / "
                                 f"{r['median_turn_rad_s']:.2f} rad/s")
            lines.append(f"| {person} | {seed} | " + " | ".join(cells) + " |")
    lines += ["", f"Paired ratios of completion time, per person (mean over run seeds; a run not finished "
                  f"counts as the cap, {cap_s:g} s):", ""]
    lines += [c.line() for c in compared]
    lines.append(f"- the paper's gesture / joystick ratio: {PAPER_RATIO[0]} +- {PAPER_RATIO[1]}")
    if failed:
        lines += ["", f"Runs failed with an error after a retry ({len(failed)}):", ""]
        lines += [f"- {f['person']} {f['condition']} run seed {f['run_seed']}: {f['error']}" for f in failed]
    if engine_line:
        lines += ["", engine_line]
    return "\n".join(lines) + "\n"


def plot(results: dict, conditions: Sequence[str], cap_s: float, out: Path) -> None:
    """Completion-time distributions per condition, and one line per person across the conditions."""
    from matplotlib.figure import Figure

    from rtcohand_drake.analysis.study_stats import person_time

    fig = Figure(figsize=(11, 4))
    ax, ax2 = fig.subplots(1, 2)
    per_run = [[(r["completion_s"] if r["completed"] else cap_s) for runs in results.values()
                for r in runs.get(c, {}).values() if r is not None] for c in conditions]
    ax.boxplot(per_run, showfliers=False)
    for k, times in enumerate(per_run, 1):
        jitter = np.random.default_rng(k).uniform(-0.15, 0.15, len(times))
        ax.scatter(k + jitter, times, s=6, alpha=0.4, color=f"C{k - 1}")
    ax.set_xticks(range(1, len(conditions) + 1), conditions)
    ax.axhline(cap_s, color="grey", lw=0.8, ls="--")
    ax.set_ylabel(f"completion time (s); not done = cap ({cap_s:g} s)")
    ax.set_title("completion time per run")
    for runs in results.values():
        times = [person_time(runs.get(c, {}), cap_s) for c in conditions]
        ax2.plot(range(len(conditions)), [np.nan if t is None else t for t in times], color="C0", alpha=0.25, lw=0.8,
                 marker=".")
    ax2.set_xticks(range(len(conditions)), conditions)
    ax2.set_ylabel("person's mean completion time (s)")
    ax2.set_title("paired: one line per person")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def _int_list(text: str) -> list[int]:
    """'100-119' or '100' as a list of ints (the command line's population ranges)."""
    try:
        if "-" in text.strip("-"):
            a, b = (int(v) for v in text.split("-", 1))
            values = list(range(a, b + 1))
        else:
            values = [int(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a seed such as 100 or a range such as 100-119, got {text!r}") from None
    if not values or min(values) < 0:
        raise argparse.ArgumentTypeError(f"expected seeds >= 0 and a range from low to high, got {text!r}")
    return values


def make_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m rtcohand_drake.study", description=__doc__.splitlines()[0])
    p.add_argument("--populations", type=_int_list, nargs="+", default=[[100], [101], [102]],
                   help="population seeds, or ranges such as 100-119 (five out-sample people each)")
    p.add_argument("--users", nargs="+", default=list(OUT_SAMPLE))
    p.add_argument("--conditions", nargs="+", choices=CONDITIONS, default=None,
                   help="default: all four; with --recorded-people: responsive intent")
    p.add_argument("--recorded-people", type=Path, default=None,
                   help="a gesture dataset file of recorded people: run them with the recorded gesture source "
                        "(analysis.recorded_study) instead of the generated populations")
    p.add_argument("--people", nargs="+", default=None, help="with --recorded-people: these people (default: all)")
    p.add_argument("--scenario", default=None,
                   help="with --recorded-people: the scenario the runs use, a built-in name or a YAML path "
                        "(default: inspection)")
    p.add_argument("--no-hand-sign", action="store_true",
                   help="with --recorded-people: run a copy of the scenario with the pause hand sign off")
    p.add_argument("--run-seeds", type=non_negative_int, nargs="+", default=None,
                   help="the runs' --seed (the people's decision rhythm), each person runs each (default: 0)")
    p.add_argument("--seed", type=non_negative_int, default=None, help="one run seed (the same as --run-seeds N)")
    p.add_argument("--cap", type=positive_float, default=None, help="the runs' time cap (s; default: the scenario's)")
    p.add_argument("--model", type=Path, default=None,
                   help="the policy file of the gesture conditions (default: the scenario's)")
    p.add_argument("--workers", "--jobs", type=non_negative_int, default=2,
                   help="local cluster worker processes; 0 runs in this process")
    p.add_argument("--address", default=None, help="an existing Dask scheduler to run on (tcp://HOST:8786)")
    p.add_argument("--runs-per-worker", type=non_negative_int, default=0,
                   help="restart the Dask workers after this many runs each (0: never); a worker's memory grows "
                        "by about 14 MB a run (docs/studies.md)")
    p.add_argument("--bootstrap", type=non_negative_int, default=10000, help="bootstrap resamples for the intervals")
    p.add_argument("--out", type=Path, default=Path("docs/results/study"))
    p.add_argument("--logs", type=Path, default=None, help="where the run logs go (default: OUT/logs)")
    p.add_argument("--summarise-only", action="store_true",
                   help="run nothing: summarise the run logs already in the logs folder")
    p.add_argument("--resume", action="store_true",
                   help="summarise the runs whose logs are already in the logs folder, run only the others")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    p = make_parser()
    args = p.parse_args(argv)
    if args.bootstrap < 1:
        p.error(f"--bootstrap must be at least 1, got {args.bootstrap}")
    if args.model is not None:
        from rtcohand_drake.learning.policy_file import check_policy_file

        check_policy_file(args.model)  # a missing or damaged file: one line now, not in every run
    if args.address is not None and not re.fullmatch(r"(tcp://)?[^\s:/]+:\d+", args.address):
        p.error(f"--address {args.address!r}: give a Dask scheduler as tcp://HOST:PORT")
    if args.recorded_people is not None:
        from rtcohand_drake.analysis.recorded_study import main_recorded

        return main_recorded(args)
    if args.people is not None or args.no_hand_sign or args.scenario is not None:
        p.error("--people, --scenario and --no-hand-sign go with --recorded-people")
    args.conditions = args.conditions or list(CONDITIONS)
    from rtcohand_drake.systems.gestures.simulated_person import population_user_ids

    unknown = [u for u in args.users if u not in population_user_ids()]
    if unknown:
        p.error(f"--users: unknown {', '.join(unknown)}; valid ids: {', '.join(population_user_ids())}")
    model = str(args.model.resolve()) if args.model is not None else None
    from rtcohand_drake.analysis.engine import Outcome, run_tasks
    from rtcohand_drake.repo_paths import repo_relative
    from rtcohand_drake.scenario import load_scenario

    populations = [n for group in args.populations for n in group]
    seeds = args.run_seeds or [args.seed if args.seed is not None else 0]
    cap = args.cap if args.cap is not None else load_scenario("inspection").duration_s
    logs = (args.logs or args.out / "logs").resolve()
    logs.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    keys = [(pop, user, c, seed) for pop in populations for user in args.users for seed in seeds
            for c in args.conditions]
    engine_line = ""
    done = {}
    if args.summarise_only or args.resume:
        for key in keys:
            path = logs / log_name(*key, model)
            if path.is_file():
                try:
                    done[key] = Outcome(key, {**summarise(str(path)), "log": str(path)}, attempts=1)
                except Exception as err:  # an unreadable log: reported, and run again with --resume
                    print(f"note: {path.name}: cannot be read ({type(err).__name__}); "
                          + ("running it again" if args.resume else "left out"), file=sys.stderr)
    if args.summarise_only:
        outcomes = [done[k] for k in keys if k in done]
        if not outcomes:
            raise InputError(f"--summarise-only: no run log of these runs in {logs}")
    else:
        def describe(o: Outcome) -> str:
            pop, user, c, seed = o.key
            state = f"{o.value['completion_s']:.1f} s" if o.value["completed"] else f"not done ({o.value['faces']}/6)"
            return f"population {pop} {user} {c} run seed {seed}: {state} ({o.seconds:.0f} s wall)"

        todo = [k for k in keys if k not in done]
        if done:
            print(f"resuming: {len(done)} runs already in {logs}, {len(todo)} to run", file=sys.stderr)
        report = run_tasks(run_condition, [(k, (k[0], k[1], k[2], str(logs), k[3], args.cap, model)) for k in todo],
                           workers=args.workers, address=args.address, label="study", describe=describe,
                           runs_per_worker=args.runs_per_worker)
        ran = {o.key: o for o in report.outcomes}
        outcomes = [done.get(k) or ran[k] for k in keys]
        engine_line = engine_summary(report) + (f" ({len(done)} more runs summarised from earlier logs.)"
                                                if done else "")
    results, failed = collect(outcomes, args.conditions)
    compared = comparisons(results, args.conditions, cap, args.bootstrap)  # bootstrap once, for both files
    table = markdown(results, args.conditions, cap, compared, failed, engine_line)
    if model:
        table = f"The gesture conditions read the policy file `{args.model}`.\n\n" + table
    print(table)
    (args.out / "study.md").write_text(table)
    def relative_log(run):  # the file is committed: its paths are the repository's (repo_paths)
        return {**run, "log": repo_relative(run["log"])} if run and "log" in run else run

    summary = {"populations": populations, "run_seeds": seeds, "cap_s": cap, "conditions": args.conditions,
               "model": repo_relative(model) if model else None,
               "results": {person: {c: {str(s): relative_log(r) for s, r in runs.items()} for c, runs in by_c.items()}
                           for person, by_c in results.items()},
               "failed": failed,
               "comparisons": [dc.asdict(c) for c in compared]}
    (args.out / "study.json").write_text(json.dumps(summary, indent=1))
    plot(results, args.conditions, cap, args.out / "study.png")
    print(f"wrote {args.out / 'study.md'}, study.json and study.png")
    return 1 if failed else 0


def engine_summary(report, projections: Sequence[int] = (16, 64, 256)) -> str:
    """Wall time, throughput per worker (start-up included) and what it projects for larger clusters."""
    done = sum(o.ok for o in report.outcomes)
    per_worker_h = report.throughput_per_worker_h()
    text = (f"Engine: {report.engine}, {report.workers} worker(s); {done}/{len(report.outcomes)} runs in "
            f"{report.wall_s / 60:.1f} min wall; {per_worker_h:.0f} runs per worker-hour (start-up included)")
    if per_worker_h > 0:
        text += "; the same runs would take, at that rate, " + ", ".join(
            f"{len(report.outcomes) / (per_worker_h * w) * 60:.1f} min on {w}" for w in projections) + " workers"
    memory = report.peak_memory_gb()
    if memory is not None:
        text += f"; largest peak memory of a process that ran them: {memory:.2f} GB"
    return text + "."


def entry_point() -> None:
    import sys

    sys.exit(run_cli(main, prog="rtcohand_drake.study"))
