"""How far the differential IK moves the part beyond the command, on the intent reference.

    python experiments/probe_turn_swing.py [--users u10 u11 u12 u13 u14] [--seed 0] [--population-seed 0]
        [--set linear_tracking_weight=600 ...]

For each person, the inspection with `IntentPolicy` (the person's intended twist, delayed; the
rest of the loop as shipped) up to 180 s, with `diff_ik` scenario keys overridden by `--set`. Every
control period while the part moves, the linear motion of the achieved workpiece twist J v that
nobody asked for (`diff_ik.unrequested_motion`: not along the linear command, or beyond it). Prints the completion time, the peak speeds, and that motion's 90th,
99th percentile and largest value (m/s). Choose on development run seeds.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

import rtcohand_drake.systems.diff_ik as diff_ik
from rtcohand_drake.analysis.reference_policies import run_intent_reference
from rtcohand_drake.diagram import peak_speeds
from rtcohand_drake.scenario import load_scenario


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--users", nargs="+", default=["u10", "u11", "u12", "u13", "u14"])
    p.add_argument("--seed", type=int, default=0, help="the run's seed: the person's decision rhythm")
    p.add_argument("--population-seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a diff_ik key (repeatable)")
    args = p.parse_args()
    overrides = {}
    for item in args.set:
        key, _, value = item.partition("=")
        overrides[key] = json.loads(value)
    beyond: list[float] = []
    split = diff_ik.unrequested_motion

    def recording(V_achieved, V_desired):
        linear, angular = split(V_achieved, V_desired)
        beyond.append(linear)
        return linear, angular

    diff_ik.unrequested_motion = recording  # the controller looks it up at each period
    times = []
    print(f"diff_ik overrides: {overrides or 'none'}; run seed {args.seed}; population {args.population_seed}")
    print("| person | faces | completion | peak v (m/s) | peak w (rad/s) | beyond the command: p90 / p99 / max (m/s) |")
    print("|---|---|---|---|---|---|")
    for user in args.users:
        scenario = load_scenario("inspection")
        for key, value in overrides.items():
            if not hasattr(scenario.diff_ik, key):
                p.error(f"--set {key}: not a diff_ik key")
            setattr(scenario.diff_ik, key, value)
        beyond.clear()
        log = run_intent_reference(scenario, user, seed=args.seed, population_seed=args.population_seed,
                                   duration_s=180.0)
        v_peak, w_peak = peak_speeds(log.robot_time, log.robot_workpiece_pose)
        b = np.array(beyond) if beyond else np.zeros(1)
        if log.completed:
            times.append(log.completion_time)
        print(f"| {user} | {log.faces_inspected}/6 | {f'{log.completion_time:.1f} s' if log.completed else '-'} "
              f"| {v_peak:.3f} | {w_peak:.3f} | {np.percentile(b, 90):.3f} / {np.percentile(b, 99):.3f} / {b.max():.3f} |",
              flush=True)
    print(f"median completion: {np.median(times):.1f} s ({len(times)}/{len(args.users)} complete)" if times else "none complete")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
