"""How well a policy reads the out-sample people of generated populations, next to the fitted reference.

    python benchmarks/report_populations.py --model PATH.pt --population-seeds 0 2 [--checkpoint CKPT]
        [--correction-weight W] [--closed-loop [--run-seed 0] [--duration 180]] [--out DIR]

For each population (`data.generate --users 15 --seed N`, written to
out/population15_sN.h5 when missing) and each of its five out-sample people:

- the Own error: each of the person's 72 clips held out in six folds, the
  other clips as context, squared error as a share of always commanding zero
  twist, for the policy and for the ridge fitted to the same folds
  (`rtcohand_drake.context_reading`'s definition);
- the reading gains of the 12 motions (median over clips): the person's
  median and their weakest motion;
- with `--closed-loop`, the inspection task through the run command
  (`benchmarks/bench_inspection.py`), with the policy and with the intent
  reference, one seed: completions and median completion times.

Choose settings on development populations (seeds 0-99); report once on
seeds of 100 or more.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OUT_SAMPLE = ("u10", "u11", "u12", "u13", "u14")


def reading(model: str, user: str, seed: int, weight: float | None) -> dict:
    from rtcohand_drake.analysis.context_reading import (
        builtin_clips,
        held_out_means,
        held_out_readings,
        held_out_reference_means,
        motion_table,
    )
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.scenario import load_scenario

    w = load_scenario("inspection").policy.correction_weight if weight is None else weight
    module = load_policy(model)
    # A file that reads the hand's path and shape gets it with the 36 (the policy box gives it the same).
    clips = builtin_clips(user, 10.0, seed, path_shape=int(module.feature_dim) > 36)
    means = held_out_means(module, clips, 6, w)
    reference = held_out_reference_means(clips, 6)
    zero = sum(float((c.labels ** 2).sum()) for c in clips)
    err = lambda ms: sum(float(((m - c.labels) ** 2).sum()) for m, c in zip(ms, clips)) / zero
    rows = motion_table(held_out_readings(None, clips, means=means))
    ref_rows = motion_table(held_out_readings(None, clips, means=reference))
    gains = [g for _, _, g, _ in rows]
    return {"own": err(means), "own_ridge": err(reference), "median_gain": float(np.median(gains)),
            "min_gain": float(min(gains)), "ridge_median_gain": float(np.median([g for _, _, g, _ in ref_rows])),
            "gains": {name: g for name, _, g, _ in rows}}


def closed_loop(model: str, seed: int, weight: float | None, intent: bool, out: Path, run_seed: int = 0,
                duration: float = 180.0) -> dict:
    cmd = [sys.executable, str(REPO / "benchmarks" / "bench_inspection.py"), "--population-seed", str(seed),
           "--seed", str(run_seed), "--workers", "2", "--out", str(out), "--duration", str(duration)]
    cmd += ["--intent"] if intent else ["--model", model]
    if weight is not None and not intent:
        cmd += ["--correction-weight", str(weight)]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    if done.returncode:  # a crashed run must not read as "not complete"
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise SystemExit(f"error: bench_inspection.py (population {seed}, {'intent' if intent else model}) "
                         f"exited with status {done.returncode}: {last}")
    text = done.stdout
    times = {}
    for user in OUT_SAMPLE:
        row = next((line for line in text.splitlines() if line.startswith(f"| {user}")), "")
        m = re.search(r"\|\s*6/6\s*\|\s*([0-9.]+) s", row)
        times[user] = float(m.group(1)) if m else None
    done = [t for t in times.values() if t is not None]
    safe = re.search(r"users completing the task safely: (\d+)/", text)
    return {"times": times, "completed": len(done), "completed_safely": int(safe.group(1)) if safe else None,
            "median_time": float(np.median(done)) if done else None, "run_seed": run_seed, "duration_s": duration,
            "table": text}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True)
    p.add_argument("--population-seeds", type=int, nargs="+", required=True)
    p.add_argument("--correction-weight", type=float, default=None, help="default: the scenario's")
    p.add_argument("--closed-loop", action="store_true")
    p.add_argument("--run-seed", type=int, default=0, help="the closed-loop runs' --seed (the people's decision rhythm)")
    p.add_argument("--duration", type=float, default=180.0, help="closed-loop cap (s)")
    p.add_argument("--out", type=Path, default=REPO / "out" / "report")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    report = {"model": args.model, "correction_weight": args.correction_weight, "populations": {}}
    for seed in args.population_seeds:
        pop = {"people": {u: reading(args.model, u, seed, args.correction_weight) for u in OUT_SAMPLE}}
        if args.closed_loop:
            pop["policy"] = closed_loop(args.model, seed, args.correction_weight, False, args.out / f"s{seed}_policy",
                                        args.run_seed, args.duration)
            pop["intent"] = closed_loop(args.model, seed, None, True, args.out / f"s{seed}_intent",
                                        args.run_seed, args.duration)
        report["populations"][seed] = pop
        print(f"population seed {seed}:")
        print("| person | Own (policy) | Own (ridge) | median gain | weakest motion | ridge median gain |")
        print("|---|---|---|---|---|---|")
        for u, r in pop["people"].items():
            print(f"| {u} | {r['own']:.3f} | {r['own_ridge']:.3f} | {r['median_gain']:+.2f} | "
                  f"{r['min_gain']:+.2f} | {r['ridge_median_gain']:+.2f} |")
        own = np.mean([r["own"] for r in pop["people"].values()])
        ridge = np.mean([r["own_ridge"] for r in pop["people"].values()])
        print(f"mean Own: policy {own:.3f}, ridge {ridge:.3f} of zero twist")
        if args.closed_loop:
            for kind in ("policy", "intent"):
                c = pop[kind]
                print(f"closed loop, {kind} (run seed {c['run_seed']}, cap {c['duration_s']:.0f} s): "
                      f"{c['completed']}/5 complete ({c['completed_safely']}/5 safely), median "
                      f"{c['median_time'] if c['median_time'] is None else round(c['median_time'], 1)} s "
                      f"({', '.join(f'{u} {t}' for u, t in c['times'].items())})")
        sys.stdout.flush()
    (args.out / "report.json").write_text(json.dumps(report, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
