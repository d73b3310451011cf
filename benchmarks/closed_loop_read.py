"""The policy's read in the closed-loop task: lag and gain against what each simulated person means.

    python benchmarks/closed_loop_read.py --population-seeds 0 2 3 [--scenario S] [--model PATH.pt] [--run-seed 0]
        [--users u10 .. u14] [--correction-weight W] [--intent] [--workers 2 | --address tcp://HOST:8786] [--out DIR]
    python benchmarks/closed_loop_read.py --logs RUN.h5 ... [--out DIR]

For each out-sample person of each population, the inspection runs in closed
loop as `python -m rtcohand_drake.run --user U --population-seed N` does,
until the hold after the sixth face (cap: the scenario's), and the policy's
output is compared with the person's intended twist every policy period
(`rtcohand_drake.analysis.closed_loop_read`): the lag that best aligns them,
each used axis's gain at that lag (1 = the person's own speed), the output
while the person intends nothing, the supervisor's command once the person
has intended nothing for 1 s (the part should be still), and the completion
time. `--intent` puts
the intent reference (the intended twist 0.3 s late) in the policy's place:
its rows read 300 ms and gains of 1, the calibration of the measure.

With `--logs`, the same figures come from run logs already written (`run --log`, the logs of
`study` and `report_populations.py --closed-loop`; `analysis.closed_loop_read.from_run_log`): a
simulated person's intended twist, or for a recorded person the label of the frame played.

Writes DIR/closed_loop_read.md and .json. Choose settings on development
populations (seeds 0-99).
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import sys
from pathlib import Path

import numpy as np

from rtcohand_drake.analysis.closed_loop_read import AXES, markdown, measure_person
from rtcohand_drake.analysis.engine import run_tasks
from rtcohand_drake.scenario import load_scenario

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--population-seeds", type=int, nargs="+", default=None)
    p.add_argument("--logs", type=Path, nargs="+", default=None,
                   help="measure these run logs (a simulated or recorded person's runs) instead of running")
    p.add_argument("--scenario", default="inspection", help="built-in scenario name or YAML path")
    p.add_argument("--model", type=Path, default=None, help="a policy file (default: the scenario's)")
    p.add_argument("--run-seed", type=int, default=0, help="the runs' --seed (the people's decision rhythm)")
    p.add_argument("--users", nargs="+", default=["u10", "u11", "u12", "u13", "u14"])
    p.add_argument("--correction-weight", type=float, default=None, help="default: the scenario's")
    p.add_argument("--intent", action="store_true", help="the intent reference in the policy's place")
    p.add_argument("--direct-share", type=float, default=None,
                   help="draw the populations with this share of direct users (data.generate --direct-share)")
    p.add_argument("--repeated-rhythm-share", type=float, default=None,
                   help="draw the populations with this share of repeated rhythm (data.generate --repeated-rhythm-share)")
    p.add_argument("--workers", type=int, default=2, help="local Dask cluster worker processes (0: in this process)")
    p.add_argument("--address", default=None, help="an existing Dask scheduler to run on (tcp://HOST:8786)")
    p.add_argument("--out", type=Path, default=REPO / "out" / "closed_loop_read")
    args = p.parse_args(argv)
    if (args.logs is None) == (args.population_seeds is None):
        p.error("give --population-seeds (run the people) or --logs (measure run logs), not both")
    if args.logs is not None:
        from rtcohand_drake.analysis.closed_loop_read import from_run_log

        from rtcohand_drake.errors import InputError

        rows = []
        for path in args.logs:
            try:
                rows.append(from_run_log(path))
            except InputError as err:
                print(f"skipped: {err}", file=sys.stderr)
        if not rows:
            print("error: no run log could be measured", file=sys.stderr)
            return 2
        return _report(args, rows, f"run logs ({len(rows)})", {"logs": [str(p) for p in args.logs]})
    scenario = load_scenario(args.scenario)
    if args.model is not None:
        scenario.policy.model = str(args.model.resolve())
    if args.correction_weight is not None:
        scenario.policy.correction_weight = args.correction_weight
    def describe(o) -> str:
        r = o.value
        return (f"p{r.population_seed}/{r.user}: completion {r.completion_s}, lag {r.lag_s * 1e3:.0f} ms, gains "
                + " ".join(f"{a} {g:+.2f}" for a, g in zip(AXES, r.gains) if np.isfinite(g)))

    from dataclasses import replace

    from rtcohand_drake.data.population import GeneratorConfig

    generator = GeneratorConfig()
    if args.direct_share is not None:
        generator = replace(generator, p_direct=args.direct_share)
    if args.repeated_rhythm_share is not None:
        generator = replace(generator, p_repeated_rhythm=args.repeated_rhythm_share)
    tasks = [((population, user), (scenario, user, population, args.run_seed, 0.3 if args.intent else None, None,
                                   generator)) for population in args.population_seeds for user in args.users]
    report = run_tasks(measure_person, tasks, workers=args.workers, address=args.address, label="closed loop",
                       describe=describe)
    if report.failed:
        for o in report.failed:
            print(f"error: p{o.key[0]}/{o.key[1]} failed after {o.attempts} attempts: {o.error}", file=sys.stderr)
        return 1
    rows = [o.value for o in report.outcomes]
    what = f"{'intent reference' if args.intent else f'policy {scenario.policy.model}'}, run seed {args.run_seed}"
    return _report(args, rows, what, {"model": scenario.policy.model, "intent": args.intent, "run_seed": args.run_seed,
                                      "direct_share": generator.p_direct,
                                      "repeated_rhythm_share": generator.p_repeated_rhythm})


def _report(args, rows, what: str, header: dict) -> int:
    table = markdown(rows)
    used = np.array([r.gains for r in rows])
    lags = [r.lag_s for r in rows]
    done = [r.completion_s for r in rows if r.completion_s is not None]
    times = [r.completion_s if r.completion_s is not None else np.inf for r in rows]  # not done: the slowest
    summary = (f"\n{what}: {len(done)}/{len(rows)} complete, median completion "
               f"{np.median(times):.1f} s (a run not done counted as the slowest); median lag {np.median(lags) * 1e3:.0f} ms; "
               "median gain per axis " + ", ".join(
                   f"{a} {np.nanmedian(used[:, d]):+.2f}" if np.isfinite(used[:, d]).any() else f"{a} -"
                   for d, a in enumerate(AXES))
               + f"; still command: median {np.nanmedian([r.still_w_rad_s for r in rows]):.3f} rad/s, "
               f"{np.nanmedian([r.still_v_m_s for r in rows]) * 1e3:.1f} mm/s, moving in "
               f"{np.nanmedian([r.still_moving_share for r in rows]):.0%} of the still samples\n")
    print(table + summary)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "closed_loop_read.md").write_text(table + summary)
    (args.out / "closed_loop_read.json").write_text(json.dumps({**header, "rows": [dc.asdict(r) for r in rows]},
                                                                indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
