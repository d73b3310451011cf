"""The gesture-against-joystick study (`python -m rtcohand_drake.study`).

    python -m rtcohand_drake.study [--populations 100 101 102] [--jobs 2] [--out docs/results/study]
        [--conditions responsive paper joystick intent]

For each out-sample person (u10-u14) of each generated population, the
inspection task is run to its end (all six faces plus the run's short hold,
or the 180 s cap) in four conditions, under the same cell, IK and safety
layer:

- `responsive`: the person's own gestures, read by the shipped policy with
  their own labelled clips as context, the responsive command filter;
- `paper`: the same with the paper's filter (2 Hz mean of 10 predictions);
- `joystick`: the same person at the arm maker's joystick
  (`rtcohand_drake.systems.joystick`);
- `intent`: the person's intended twist, 0.3 s late, in place of the
  policy (what a perfect reader would get; `analysis.reference_policies`).

The paper's figure is the per-person ratio of completion times, gesture over
joystick: 1.89 +- 0.66. This prints, and writes to `--out`, a table per
person (completion time, faces, median commanded speed while moving) and the
median ratio for each gesture condition, with plots of completion times and
of faces seen over time. Runs go through the run command's own code
(`rtcohand_drake.run.main`), each in its own process, and keep their run logs.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.errors import run_cli

CONDITIONS = ("responsive", "paper", "joystick", "intent")
OUT_SAMPLE = ("u10", "u11", "u12", "u13", "u14")
PAPER_RATIO = (1.89, 0.66)
# The study's "moving" share and median speeds count a command as moving the part when the
# norm of its linear half exceeds 5 mm/s or that of its angular half 0.02 rad/s: a measure of
# the report only, so it stays fixed across scenarios (the filter's deadband, per axis, is a
# scenario key and may change).
MOVING_SPEED_M_S = 0.005
MOVING_TURN_RAD_S = 0.02


def run_condition(population: int, user: str, condition: str, out: str, seed: int = 0) -> str:
    """One run, its log written to `out`; returns the log's path."""
    log = Path(out) / f"p{population}_{user}_{condition}.h5"
    if condition == "intent":
        _run_intent(population, user, log, seed)
        return str(log)
    from rtcohand_drake.run import main

    args = ["--scenario", "inspection", "--realtime-rate", "0", "--no-meshcat", "--user", user,
            "--population-seed", str(population), "--seed", str(seed), "--log", str(log)]
    if condition == "joystick":
        args += ["--gesture-source", "joystick"]
    else:
        args += ["--filter-mode", condition]
    with contextlib.redirect_stdout(io.StringIO()):
        status = main(args)
    if status != 0:
        raise RuntimeError(f"{log.name}: the run exited with status {status}")
    return str(log)


def _run_intent(population: int, user: str, log: Path, seed: int) -> None:
    from rtcohand_drake.analysis.reference_policies import run_intent_reference
    from rtcohand_drake.run_log import write_run_log
    from rtcohand_drake.scenario import load_scenario

    write_run_log(log, run_intent_reference(load_scenario("inspection"), user, seed=seed, population_seed=population,
                                            stop_when_done=True))


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


def ratios(results: dict, condition: str) -> list[float]:
    """Per person, completion time in `condition` over the joystick's (both completed)."""
    out = []
    for person, runs in results.items():
        a, b = runs.get(condition), runs.get("joystick")
        if a and b and a["completed"] and b["completed"]:
            out.append(a["completion_s"] / b["completion_s"])
    return out


def markdown(results: dict, conditions: Sequence[str]) -> str:
    lines = ["| person | " + " | ".join(f"{c}: time (faces), median v / w" for c in conditions) + " |",
             "|---|" + "---|" * len(conditions)]
    for person, runs in results.items():
        cells = []
        for c in conditions:
            r = runs.get(c)
            if r is None:
                cells.append("-")
                continue
            time = f"{r['completion_s']:.1f} s" if r["completed"] else "not done"
            cells.append(f"{time} ({r['faces']}/6), {r['median_speed_m_s']:.3f} m/s / {r['median_turn_rad_s']:.2f} rad/s")
        lines.append(f"| {person} | " + " | ".join(cells) + " |")
    lines.append("")
    for c in conditions:
        if c == "joystick":
            continue
        r = ratios(results, c)
        done = sum(1 for runs in results.values() if runs.get(c) and runs[c]["completed"])
        lines.append(f"- **{c} / joystick completion time**: median {statistics.median(r):.2f} "
                     f"(mean {np.mean(r):.2f} +- {np.std(r):.2f}, {len(r)} people); "
                     f"{c} completed {done}/{len(results)}" if r else f"- {c}: no person completed both")
    done = sum(1 for runs in results.values() if runs.get("joystick") and runs["joystick"]["completed"])
    lines.append(f"- joystick completed {done}/{len(results)}; the paper's gesture / joystick ratio: "
                 f"{PAPER_RATIO[0]} +- {PAPER_RATIO[1]}")
    return "\n".join(lines) + "\n"


def plot(results: dict, conditions: Sequence[str], out: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4))
    ax, ax2 = fig.subplots(1, 2)
    people = list(results)
    width = 0.8 / len(conditions)
    for k, c in enumerate(conditions):
        times = [results[p][c]["completion_s"] if results[p].get(c) and results[p][c]["completed"] else np.nan
                 for p in people]
        ax.bar(np.arange(len(people)) + k * width, times, width, label=c)
    ax.set_xticks(np.arange(len(people)) + 0.4 - width / 2, people, rotation=60, fontsize=7)
    ax.set_ylabel("completion time (s); missing = not done")
    ax.legend(fontsize=8)
    ax.set_title("inspection completion per person")
    for k, c in enumerate(conditions):
        for p in people:
            r = results[p].get(c)
            if r is None:
                continue
            t = [0.0] + r["face_times_s"]
            ax2.step(t, np.arange(len(t)), where="post", color=f"C{k}", alpha=0.35, lw=1)
        ax2.plot([], [], color=f"C{k}", label=c)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("faces inspected")
    ax2.legend(fontsize=8)
    ax2.set_title("faces over time (one line per person)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.study", description=__doc__.splitlines()[0])
    p.add_argument("--populations", type=int, nargs="+", default=[100, 101, 102])
    p.add_argument("--users", nargs="+", default=list(OUT_SAMPLE))
    p.add_argument("--conditions", nargs="+", choices=CONDITIONS, default=list(CONDITIONS))
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("docs/results/study"))
    p.add_argument("--logs", type=Path, default=None, help="where the run logs go (default: OUT/logs)")
    p.add_argument("--summarise-only", action="store_true",
                   help="run nothing: summarise the run logs already in the logs folder (people with any)")
    args = p.parse_args(argv)
    logs = args.logs or args.out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(pop, user, c) for pop in args.populations for user in args.users for c in args.conditions]
    results: dict = {f"p{pop}/{user}": {} for pop in args.populations for user in args.users}
    if args.summarise_only:
        for pop, user, c in jobs:
            path = logs / f"p{pop}_{user}_{c}.h5"
            if path.is_file():
                results[f"p{pop}/{user}"][c] = summarise(str(path))
        results = {person: runs for person, runs in results.items() if runs}
        return _report(results, args)
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = {pool.submit(run_condition, pop, user, c, str(logs), args.seed): (pop, user, c)
                   for pop, user, c in jobs}
        for n, future in enumerate(futures, 1):
            pop, user, c = futures[future]
            try:
                results[f"p{pop}/{user}"][c] = summarise(future.result())
                r = results[f"p{pop}/{user}"][c]
                state = f"{r['completion_s']:.1f} s" if r["completed"] else f"not done ({r['faces']}/6)"
            except Exception as err:  # one failed run is reported, not fatal
                state = f"failed: {err}"
            print(f"[{n}/{len(jobs)}] population {pop} {user} {c}: {state}", flush=True)
    return _report(results, args)


def _report(results: dict, args) -> int:
    table = markdown(results, args.conditions)
    print(table)
    (args.out / "study.md").write_text(table)
    (args.out / "study.json").write_text(json.dumps({"populations": args.populations, "seed": args.seed,
                                                     "results": results}, indent=1))
    plot(results, args.conditions, args.out / "study.png")
    print(f"wrote {args.out / 'study.md'}, study.json and study.png")
    return 0


def entry_point() -> None:
    import sys

    sys.exit(run_cli(main, prog="rtcohand_drake.study"))
