"""The kernel read's share A that a policy file chooses for each simulated person of a study.

    python benchmarks/person_blend.py --populations 121-140 [--model models/cchp_path_shape.pt] [--out FILE.json]

A file that reads the hand's path and shape (`learning.path_shape_policy` with `--folds`) chooses A,
the kernel read's share of the mean, for each person when their context is encoded: the least-squares
blend of the kernel read and the CCHP over the person's own clips, clamped to [0, 1]. For a person
with A = 0 the file steps exactly as the CCHP inside it, so a closed-loop run gives the same log as the
run of the CCHP's own file. This prints A for each out-sample person of each population, with the
context the run command builds for them (`--gesture-source synthetic`), and how many have A = 0.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def _populations(text: str) -> list[int]:
    if "-" in text:
        lo, hi = (int(v) for v in text.split("-", 1))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(",")]


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.errors import InputError
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.run import make_parser
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.registry import make_gesture_source
    from rtcohand_drake.analysis.study import OUT_SAMPLE as OUT_SAMPLE_USERS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--populations", required=True, help="a range (121-140) or a list (121,125)")
    p.add_argument("--model", default="models/cchp_path_shape.pt")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    try:
        module = load_policy(args.model)
    except (InputError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if not hasattr(module, "_blend"):
        print(f"error: {args.model} does not blend a kernel read (not a path-and-shape file)", file=sys.stderr)
        return 2
    scenario = load_scenario("inspection")
    blends = {}
    for population in _populations(args.populations):
        for user in OUT_SAMPLE_USERS:
            run_args = make_parser().parse_args(["--scenario", "inspection", "--user", user, "--population-seed",
                                                 str(population), "--realtime-rate", "0", "--no-meshcat"])
            pieces = make_gesture_source("synthetic", run_args, scenario).default_context(path_shape=True)
            x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
            with torch.no_grad():
                keys, _, _, _ = module.encode_context(x_c, y_c, mask)
            blends[f"p{population}/{user}"] = float(module._blend(keys))
            print(f"p{population}/{user}: A = {blends[f'p{population}/{user}']:.3f}", flush=True)
    a = np.array(list(blends.values()))
    print(f"{len(a)} people: A = 0 for {int(np.sum(a == 0.0))}; median {np.median(a):.3f}, "
          f"quartiles {np.percentile(a, 25):.3f}-{np.percentile(a, 75):.3f}, max {a.max():.3f}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"model": args.model, "blends": blends}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
