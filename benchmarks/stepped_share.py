"""Policy files stepped as the policy box steps them, on one evaluation setting: the share of the zero twist's error.

    python benchmarks/stepped_share.py --data population118.h5 --models models/cchp_path_shape.pt models/cchp_default.pt
        [--setting Own] [--every 3] [--out FILE.json]

Every `--every`-th episode of the setting (`data.sampling.evaluation_episodes`, seed 0) is read by
each file with `learning.evaluate.stepped_policy_mse`: the context encoded once, the file's own mean
fed back, z the mean of q(z|C). Files that read the hand's path and shape get it from the dataset
(`to_policy_clip(path_shape=True)`). Prints, per file, the MSE and its share of the MSE of commanding
zero twist over the same episodes.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.errors import InputError
    from rtcohand_drake.learning.evaluate import stepped_policy_mse
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True)
    p.add_argument("--models", nargs="+", required=True)
    p.add_argument("--setting", default="Own")
    p.add_argument("--every", type=int, default=3)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    if args.every < 1:
        raise SystemExit("error: --every must be at least 1")
    torch.set_num_threads(1)
    try:
        modules = {m: load_policy(m) for m in args.models}
        wide = any(int(m.feature_dim) > FEATURE_DIM for m in modules.values())
        episodes = {w: evaluation_episodes(load_clips(args.data, 10.0, path_shape=w), args.setting, 0)[::args.every]
                    for w in {False, wide}}
    except (InputError, ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    chosen = episodes[False]
    if not chosen:
        print(f"error: {args.data} has no {args.setting} episodes", file=sys.stderr)
        return 2
    zero = float(np.mean([np.mean(np.asarray(e.target.labels, np.float64) ** 2) for e in chosen]))
    out = {"data": args.data, "setting": args.setting, "every": args.every, "episodes": len(chosen),
           "zero_twist_mse": zero, "models": {}}
    print(f"{args.data}: {len(chosen)} {args.setting} episodes (every {args.every}th); zero twist MSE {zero:.6f}")
    for name, module in modules.items():
        r = stepped_policy_mse(module, episodes[int(module.feature_dim) > FEATURE_DIM])
        out["models"][name] = {"mse": r["mse"], "share_of_zero": r["mse"] / zero}
        print(f"  {name}: MSE {r['mse']:.7f}, {r['mse'] / zero:.5f} of zero twist", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
