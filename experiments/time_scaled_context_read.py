"""Development probe: the kernel read of the hand's path and shape, its context widened by time-scaled copies.

    python experiments/time_scaled_context_read.py --data FILE.h5 [--setting Person] [--factors 0.8 1.25]

A recorded person gives 2-4 examples of each gesture, and repeats them faster or slower than their
examples. Each context clip is also played f times as long (its frames f x their interval apart,
its labels stretched with them), for each f given, and the kernel read (`learning.kernel_reference`,
bandwidth 0.5, lambda 0.3, as the policy file for real hands) is fitted to the context with those
copies. Prints each read's share of the zero twist's squared error, without and with the copies.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np


def time_scaled(clip, factor: float):
    """The clip played `factor` times as long: the same frames and labels, further apart in time."""
    if clip.timestamps is not None:
        return dataclasses.replace(clip, timestamps=np.asarray(clip.timestamps, np.float64) * factor)
    return dataclasses.replace(clip, fps=clip.fps / factor)


def main(argv=None):
    from rtcohand_drake.data.dataset import read_dataset, to_policy_clip
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.kernel_reference import KernelReference

    p = argparse.ArgumentParser()
    p.add_argument("--data", required=True)
    p.add_argument("--setting", default="Person")
    p.add_argument("--factors", type=float, nargs="+", default=[0.8, 1.25])
    p.add_argument("--sets", nargs="+", default=None,
                   help="factor sets to compare, each comma-separated (default: none, then --factors)")
    p.add_argument("--scale", type=float, default=0.5)
    p.add_argument("--lam", type=float, default=0.3)
    args = p.parse_args(argv)
    sets = [()] + ([tuple(float(v) for v in s.split(",")) for s in args.sets] if args.sets else [tuple(args.factors)])
    raw = [c for c in read_dataset(args.data) if c.object_velocity is not None]
    by_name = {c.name: c for c in raw}
    clips = [to_policy_clip(c) for c in raw]
    by_id = {id(c.features): c.name for c in clips}
    factors = sorted({f for s in sets for f in s} | {1.0})
    policy = {(n, f): to_policy_clip(c if f == 1.0 else time_scaled(c, f), path_shape=True)
              for n, c in by_name.items() for f in factors}
    width = clips[0].features.shape[1]
    episodes = evaluation_episodes(clips, args.setting, 0)
    sums: dict = {}
    for i, e in enumerate(episodes):
        y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
        names = [by_id[id(px)] for px, _ in e.context]
        query = policy[(e.target.name, 1.0)].features[:, width:].astype(np.float64)
        for s in sets:
            pieces = [policy[(n, f)] for n in names for f in (1.0,) + s]
            x = np.concatenate([pc.features[:, width:] for pc in pieces]).astype(np.float64)
            lab = np.nan_to_num(np.concatenate([pc.labels for pc in pieces]).astype(np.float64))
            read = KernelReference(args.scale, args.lam, start=0).fit([(x, lab)]).predict(query)
            key = "the clips as recorded" if not s else "+ played " + ", ".join(f"{f:g}x" for f in s) + " as long"
            err, zero = sums.get(key, (0.0, 0.0))
            sums[key] = (err + np.mean((read - y) ** 2), zero + np.mean(y ** 2))
        if i % 20 == 0:
            print(f"{i + 1}/{len(episodes)}", file=sys.stderr)
    print(f"{args.data} {args.setting}: {len(episodes)} episodes; kernel read, shares of zero twist")
    for name, (err, zero) in sorted(sums.items(), key=lambda kv: kv[1][0] / kv[1][1]):
        print(f"  {err / zero:.3f}  {name}")


if __name__ == "__main__":
    main()
