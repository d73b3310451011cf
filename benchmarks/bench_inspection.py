"""The inspection task for each out-sample user, through the run CLI itself.

    python benchmarks/bench_inspection.py [--model PATH.pt] [--users u10 u11 u12 u13 u14]
        [--duration 120] [--workers 2 | --address tcp://HOST:8786] [--out DIR] [--seed 0] [--filter-mode paper|responsive]
        [--correction-weight W] [--population-seed N] [--intent [--intent-delay 0.3]]

Runs `python -m rtcohand_drake.run --scenario inspection --realtime-rate 0
--no-meshcat --user U --duration D --log DIR/U.h5` for each user (the
built-in simulated person is that user, acting in closed loop; the policy's
context is that user's own labelled clips) and prints one table row per user
from the run log: faces inspected, completion time, the closest approach to
the mold walls and of the arm, gripper and part to the cell (table, mold,
glass), the peak workpiece speeds against the scenario's limits, the
largest joint position and speed over the model's limits, and the safety
events. The goal: all six faces within 120 s, no mold or cell contact and no
limit exceeded, for at least 4 of the 5 users.

`--intent` is a reference for the rest of the loop: the policy is replaced by
the simulated person's own intended twist, delayed (`IntentPolicy`), so the
table shows what filter, supervisor, IK and arm achieve with a policy that
reads every gesture right.

`--correction-weight W` runs a copy of the scenario with `policy.correction_weight: W`;
`--population-seed N` takes the five out-sample users of another generated
population (`data.generate --seed N`): people other than the benchmark's, on
whom a setting can be chosen before the benchmark is run.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from rtcohand_drake.analysis.engine import run_tasks
from rtcohand_drake.analysis.inspection import joint_excess
from rtcohand_drake.analysis.study import engine_summary
from rtcohand_drake.diagram import peak_speeds
from rtcohand_drake.run_log import read_run_log
from rtcohand_drake.scenario import load_scenario


def run_user(user: str, args, out: Path) -> tuple[str, int, str]:
    log = out / f"{user}.h5"
    cmd = [sys.executable, "-m", "rtcohand_drake.run", "--scenario", args.scenario, "--realtime-rate", "0",
           "--no-meshcat", "--user", user, "--duration", str(args.duration), "--log", str(log),
           "--seed", str(args.seed), "--population-seed", str(args.population_seed)]
    if args.model:
        cmd += ["--model", args.model]
    if args.filter_mode:
        cmd += ["--filter-mode", args.filter_mode]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise RuntimeError(f"the run command exited with status {done.returncode}: {last}")
    return user


def run_user_reference(user: str, args, out: Path) -> tuple[str, int, str]:
    """The same task with `IntentPolicy` (the person's intended twist, delayed) in place of CCHP."""
    from rtcohand_drake.analysis.reference_policies import run_intent_reference
    from rtcohand_drake.run_log import write_run_log

    scenario = load_scenario(args.scenario)
    if args.filter_mode:
        scenario.command_filter.mode = args.filter_mode
    log = run_intent_reference(scenario, user, seed=args.seed, population_seed=args.population_seed,
                               delay_s=args.intent_delay, duration_s=args.duration)
    write_run_log(out / f"{user}.h5", log)
    return user


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default=None, help="policy file (default: the scenario's policy.model, the shipped models/cchp_default.pt)")
    p.add_argument("--scenario", default="inspection")
    p.add_argument("--users", nargs="+", default=["u10", "u11", "u12", "u13", "u14"])
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--workers", "--jobs", type=int, default=2,
                   help="local Dask cluster worker processes (0: in this process); docs/studies.md")
    p.add_argument("--address", default=None, help="an existing Dask scheduler to run on (tcp://HOST:8786)")
    p.add_argument("--seed", type=int, default=0, help="the run CLI's --seed: the operators' and the policy's draws")
    p.add_argument("--population-seed", type=int, default=0, help="the population the operators come from")
    p.add_argument("--correction-weight", type=float, default=None,
                   help="run a copy of the scenario with this policy.correction_weight")
    p.add_argument("--filter-mode", choices=("paper", "responsive"), default=None,
                   help="override the scenario's command_filter.mode (as the run CLI's flag)")
    p.add_argument("--out", default=None, help="keep the run logs here (default: a temporary folder)")
    p.add_argument("--intent", action="store_true",
                   help="reference: replace the policy by the simulated person's intended twist, delayed "
                        "(rtcohand_drake.systems.gestures.simulated_person.IntentPolicy), in this process")
    p.add_argument("--intent-delay", type=float, default=0.3, help="delay of --intent (s)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as scenario_dir:
        if args.correction_weight is not None:
            args.scenario = _with_correction_weight(args.scenario, args.correction_weight, Path(scenario_dir))
        return _run(args)


def _with_correction_weight(scenario: str, weight: float, folder: Path) -> str:
    """A copy of the scenario file with policy.correction_weight set."""
    import yaml

    from rtcohand_drake.scenario import resolve_scenario_path

    data = yaml.safe_load(resolve_scenario_path(scenario).read_text())
    data.setdefault("policy", {})["correction_weight"] = float(weight)
    path = folder / f"{data.get('name', 'scenario')}_w{weight:g}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


def _run(args) -> int:
    scenario = load_scenario(args.scenario)
    if args.filter_mode:
        scenario.command_filter.mode = args.filter_mode
    v_lim, w_lim = scenario.safety.max_linear_speed_m_s, scenario.safety.max_angular_speed_rad_s
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or tmp)
        out.mkdir(parents=True, exist_ok=True)
        one = run_user_reference if args.intent else run_user
        report = run_tasks(one, [(u, (u, args, out)) for u in args.users], workers=args.workers,
                           address=args.address, label="inspection")
        policy = (f"intended twist delayed {args.intent_delay} s (reference)" if args.intent
                  else args.model or f"models/{scenario.policy.model}")
        print(f"policy: {policy}; command filter: {scenario.command_filter.mode}; correction weight "
              f"{scenario.policy.correction_weight:g}; seed {args.seed}; limits {v_lim} m/s, {w_lim} rad/s")
        print("| user | faces | completion | mold (closest, mm) | cell (closest, mm) | peak v (m/s) | peak w (rad/s) "
              "| joint q / v over limit | events |")
        print("|---|---|---|---|---|---|---|---|---|")
        successes = 0
        for outcome in report.outcomes:
            user = outcome.key
            if not outcome.ok:
                print(f"| {user} | run failed after {outcome.attempts} attempts: {outcome.error} |")
                continue
            log = read_run_log(out / f"{user}.h5")
            v_peak, w_peak = peak_speeds(log.robot_time, log.robot_workpiece_pose)
            over_q, over_v = joint_excess(scenario, log.robot_q, log.robot_v)
            clearance = float(log.extra_attrs.get("mold_min_clearance_m", np.inf))
            touched = bool(log.extra_attrs.get("mold_touched", False))
            cell = float(log.extra_attrs.get("cell_min_clearance_m", np.inf))
            cell_touched = bool(log.extra_attrs.get("cell_touched", False))
            kinds: dict[str, int] = {}
            for e in log.events:
                kinds[e.kind] = kinds.get(e.kind, 0) + 1
            within = v_peak <= v_lim * 1.02 and w_peak <= w_lim * 1.02 and over_q <= 0 and over_v <= 0
            ok = (log.completed and log.completion_time <= args.duration and not touched and not cell_touched
                  and within)
            successes += ok
            completion = f"{log.completion_time:.1f} s" if log.completed else "-"
            mold = ("touched" if touched else "clear") + (f" ({clearance * 1e3:.1f})" if np.isfinite(clearance) else "")
            cell_text = ("TOUCHED" if cell_touched else "clear") + (f" ({cell * 1e3:.1f})" if np.isfinite(cell) else "")
            events = ", ".join(f"{k} x{n}" for k, n in sorted(kinds.items())) or "none"
            print(f"| {user} | {log.faces_inspected}/6 | {completion} | {mold} | {cell_text} | {v_peak:.3f} | {w_peak:.3f} "
                  f"| {max(over_q, 0):.3f} / {max(over_v, 0):.3f} | {events} |")
        print(f"users completing the task safely: {successes}/{len(args.users)}")
        print(engine_summary(report))
    if report.failed:
        print(f"error: {len(report.failed)} run(s) failed: " + ", ".join(str(o.key) for o in report.failed),
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
