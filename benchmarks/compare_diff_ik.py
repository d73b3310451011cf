"""The differential-IK solvers side by side on the intent reference, in one run.

    python benchmarks/compare_diff_ik.py [--solvers legacy drake_system] [--population-seeds 0 1]
        [--users u10 u11 u12 u13 u14] [--duration 120] [--jobs 2] [--scenario inspection]

For each solver (`diff_ik.solver`), population and out-sample person, the
inspection task runs with the intent reference in place of the policy (the
simulated person's intended twist, delayed 0.3 s: `bench_inspection.py
--intent`), in a process of its own. Each run stops 2 s after the last face
counts, or at `--duration`. Per solver: completions, the median completion
time, the median `ik_no_solution` and `ik_stuck` events a run, the closest
approach to the cell, and the real-time factor (simulated over wall-clock
seconds, the whole diagram); then one row per run.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

CHECK_EVERY_S = 5.0
HOLD_AFTER_S = 2.0


def run_one(job: tuple) -> dict:
    solver, population_seed, user, args = job
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.analysis.inspection import measure_inspection, score_run_log
    from rtcohand_drake.analysis.reference_policies import IntentPolicy
    from rtcohand_drake.cell.plant import eye_position
    from rtcohand_drake.diagram import build_run_diagram, collect_run_log
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person

    scenario = load_scenario(args.scenario)
    scenario.diff_ik.solver = solver
    source, _ = make_builtin_person(scenario, seed=args.seed, user=user, population_seed=population_seed)
    run = build_run_diagram(scenario, source=source, policy=IntentPolicy(scenario.policy.rate_hz, 0.3),
                            gesture_source="intent")
    simulator = Simulator(run.diagram)
    context = simulator.get_context()
    eye = eye_position(scenario.cell)
    sink = run.loggers["robot_workpiece_pose"]
    start = time.perf_counter()
    t = 0.0
    while t < args.duration:
        t = min(t + CHECK_EVERY_S, args.duration)
        simulator.AdvanceTo(t)
        log = sink.FindLog(context)
        result = measure_inspection(log.sample_times(), log.data().T, eye)
        if result.completed and t >= result.completion_time + HOLD_AFTER_S:
            break
    wall = time.perf_counter() - start
    log = collect_run_log(run, context, scenario)
    score_run_log(log, scenario)
    counts = {}
    for e in log.events:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    return {"solver": solver, "population": population_seed, "user": user, "completed": log.completed,
            "completion": log.completion_time, "faces": log.faces_inspected,
            "no_solution": counts.get("ik_no_solution", 0), "stuck": counts.get("ik_stuck", 0),
            "clearance_events": counts.get("ik_clearance", 0),
            "cell_mm": 1e3 * float(log.extra_attrs.get("cell_min_clearance_m", np.inf)),
            "touched": bool(log.extra_attrs.get("cell_touched", False)) or bool(log.extra_attrs.get("mold_touched", False)),
            "sim_s": float(context.get_time()), "wall_s": wall}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--solvers", nargs="+", default=["legacy", "drake_system"])
    p.add_argument("--population-seeds", type=int, nargs="+", default=[0])
    p.add_argument("--users", nargs="+", default=["u10", "u11", "u12", "u13", "u14"])
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--scenario", default="inspection")
    args = p.parse_args(argv)
    jobs = [(s, n, u, args) for n in args.population_seeds for u in args.users for s in args.solvers]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run_one, jobs))
    print(f"intent reference (delay 0.3 s), populations {args.population_seeds}, seed {args.seed}, "
          f"runs stop {HOLD_AFTER_S:g} s after completion or at {args.duration:g} s")
    print("| solver | completed | median completion (s) | median ik_no_solution | median ik_stuck "
          "| closest to cell (mm) | contact | real-time factor |")
    print("|---|---|---|---|---|---|---|---|")
    for solver in args.solvers:
        mine = [r for r in rows if r["solver"] == solver]
        done = [r["completion"] for r in mine if r["completed"]]
        rtf = sum(r["sim_s"] for r in mine) / sum(r["wall_s"] for r in mine)
        print(f"| {solver} | {len(done)}/{len(mine)} | {np.median(done) if done else float('nan'):.1f} "
              f"| {np.median([r['no_solution'] for r in mine]):g} | {np.median([r['stuck'] for r in mine]):g} "
              f"| {min(r['cell_mm'] for r in mine):.1f} | {sum(r['touched'] for r in mine)} | {rtf:.1f} |")
    print()
    print("| solver | population | user | faces | completion (s) | ik_no_solution | ik_stuck | ik_clearance "
          "| closest to cell (mm) | real-time factor |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        c = f"{r['completion']:.1f}" if r["completed"] else "-"
        print(f"| {r['solver']} | {r['population']} | {r['user']} | {r['faces']}/6 | {c} | {r['no_solution']} "
              f"| {r['stuck']} | {r['clearance_events']} | {r['cell_mm']:.1f} | {r['sim_s'] / r['wall_s']:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
