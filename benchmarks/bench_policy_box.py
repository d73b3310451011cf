"""What the policy box costs a policy period, with each policy file, interleaved in one process.

    taskset -c 0 python benchmarks/bench_policy_box.py [--models models/cchp_path_shape.pt models/cchp_default.pt]
        [--rounds 8] [--periods 400] [--out FILE.json]

The box (`systems.policy.CchpPolicy`) is built as the default run builds it: the scenario's policy
settings and the default run's simulated person's context (with the hand's path and shape for a file
that reads them). It is simulated alone, one period at a time, its gesture features fixed to a new
random vector each period (its keypoints, for a file that reads them, to a fixed skeleton). Each round
times `--periods` periods of each file, the files in turn (in reverse order every other round), and the
figure is the median over the rounds after the first of the mean time a period. One thread, as the
run. The run's own simulation has about 343 policy periods (34.3 s at 10 Hz), so 0.1 ms a period is
about 0.03 s of it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def build_box(model: Path):
    """The box with the default run's person as context, in a simulator of its own, inputs fixed."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.interfaces import GESTURE_FEATURES, KEYPOINTS
    from rtcohand_drake.learning.policy_file import reads_path_shape
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person
    from rtcohand_drake.systems.policy import CchpPolicy

    scenario = load_scenario("inspection")
    _, pieces = make_builtin_person(scenario, seed=0, path_shape=reads_path_shape(model))
    box = CchpPolicy.from_scenario(model, pieces, scenario.policy)
    simulator = Simulator(box)
    context = simulator.get_mutable_context()
    box.GetInputPort(GESTURE_FEATURES).FixValue(context, np.zeros(36))
    if box.HasInputPort(KEYPOINTS):
        box.GetInputPort(KEYPOINTS).FixValue(context, np.random.default_rng(1).normal(0.0, 0.05, 63))
    return box, simulator


def time_periods(box, simulator, features: np.ndarray) -> float:
    """Mean wall seconds a period over `features` (one row a period)."""
    from rtcohand_drake.interfaces import GESTURE_FEATURES

    context = simulator.get_mutable_context()
    port = box.GetInputPort(GESTURE_FEATURES)
    start, total = context.get_time(), 0.0
    for k, x in enumerate(features):
        port.FixValue(context, x)
        t = time.perf_counter()
        simulator.AdvanceTo(start + (k + 1) * box.period_s)
        total += time.perf_counter() - t
    return total / len(features)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", type=Path, nargs="+",
                   default=[REPO / "models" / "cchp_path_shape.pt", REPO / "models" / "cchp_default.pt"])
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--periods", type=int, default=400)
    p.add_argument("--out", type=Path, default=None, help="write the figures as JSON")
    args = p.parse_args(argv)
    if args.rounds < 2 or args.periods < 1:
        p.error("--rounds must be at least 2 (the first is a warm-up) and --periods at least 1")
    import torch

    from rtcohand_drake.repo_paths import repo_relative

    torch.set_num_threads(1)
    boxes = {str(repo_relative(m)): build_box(m) for m in args.models}
    features = np.random.default_rng(0).normal(0.0, 0.2, (args.periods, 36))
    rows = {name: [] for name in boxes}
    for r in range(args.rounds):
        for name in (list(boxes) if r % 2 == 0 else list(boxes)[::-1]):
            rows[name].append(time_periods(*boxes[name], features) * 1e3)
    result = {"periods": args.periods, "rounds": args.rounds, "ms_per_period": rows,
              "median_ms": {name: statistics.median(v[1:]) for name, v in rows.items()}}
    for name, v in rows.items():
        print(f"{name}: {result['median_ms'][name]:.3f} ms a period (median of rounds 2..{args.rounds}; "
              f"rounds {', '.join(f'{x:.3f}' for x in v)})")
    if args.out is not None:
        args.out.write_text(json.dumps(result, indent=1))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
