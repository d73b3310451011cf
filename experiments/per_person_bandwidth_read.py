"""Development probe: the kernel read's bandwidth and lambda chosen for each person from their own clips.

    python experiments/per_person_bandwidth_read.py --data FILE.h5 [--setting Person]
        [--bandwidths 0.35 0.5 0.7] [--lams 0.1 0.3 1] [--folds 4]

The policy file for real hands reads every person with one bandwidth (0.5 x the median distance
between the context's steps) and lambda (0.3), chosen on the development people. Here, per episode,
each (bandwidth, lambda) pair is scored on the person's own context by F folds of its clips (clip b
in fold b mod F: fitted on the other folds, read on this one), and the pair with the least error
reads the held-out clip. Prints the shares of the zero twist's squared error of the fixed setting,
of the setting chosen per person, and of each pair fixed, and how often each pair was chosen.
"""
from __future__ import annotations

import argparse
import collections
import sys

import numpy as np


def main(argv=None):
    from rtcohand_drake.data.dataset import read_dataset, to_policy_clip
    from rtcohand_drake.data.hand_features import path_shape_features
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.kernel_reference import KernelReference

    p = argparse.ArgumentParser()
    p.add_argument("--data", required=True)
    p.add_argument("--setting", default="Person")
    p.add_argument("--bandwidths", type=float, nargs="+", default=[0.35, 0.5, 0.7])
    p.add_argument("--lams", type=float, nargs="+", default=[0.1, 0.3, 1.0])
    p.add_argument("--folds", type=int, default=4)
    args = p.parse_args(argv)
    raw = [c for c in read_dataset(args.data) if c.object_velocity is not None]
    clips = [to_policy_clip(c) for c in raw]
    shape = {c.name: path_shape_features(c.keypoints, c.fps, 10.0, c.timestamps).astype(np.float64) for c in raw}
    by_id = {id(c.features): c.name for c in clips}
    episodes = evaluation_episodes(clips, args.setting, 0)
    pairs = [(b, lam) for b in args.bandwidths for lam in args.lams]
    sums: dict = {}
    chosen = collections.Counter()

    def add(name, err, zero):
        e, z = sums.get(name, (0.0, 0.0))
        sums[name] = (e + err, z + zero)

    for i, e in enumerate(episodes):
        y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
        names = [by_id[id(px)] for px, _ in e.context]
        labels = [np.nan_to_num(np.asarray(py, np.float64)) for _, py in e.context]
        xq = shape[e.target.name]
        score = {}
        for b, lam in pairs:
            err = 0.0
            for f in range(args.folds):
                fit = [j for j in range(len(names)) if j % args.folds != f]
                held = [j for j in range(len(names)) if j % args.folds == f]
                if not fit or not held:
                    continue
                ref = KernelReference(b, lam, start=0).fit(
                    [(np.concatenate([shape[names[j]] for j in fit]), np.concatenate([labels[j] for j in fit]))])
                for j in held:
                    err += float(np.sum((ref.predict(shape[names[j]]) - labels[j]) ** 2))
            score[(b, lam)] = err
        best = min(score, key=score.get)
        chosen[best] += 1
        x_all, y_all = np.concatenate([shape[n] for n in names]), np.concatenate(labels)
        zero = float(np.mean(y ** 2))
        for b, lam in pairs:
            read = KernelReference(b, lam, start=0).fit([(x_all, y_all)]).predict(xq)
            err = float(np.mean((read - y) ** 2))
            add(f"fixed: bandwidth {b:g}, lambda {lam:g}", err, zero)
            if (b, lam) == best:
                add("chosen per person by folds of their clips", err, zero)
        if i % 10 == 0:
            print(f"{i + 1}/{len(episodes)}", file=sys.stderr)
    print(f"{args.data} {args.setting}: {len(episodes)} episodes; kernel read, shares of zero twist")
    for name, (err, zero) in sorted(sums.items(), key=lambda kv: kv[1][0] / kv[1][1]):
        print(f"  {err / zero:.3f}  {name}")
    print("chosen: " + ", ".join(f"({b:g}, {lam:g}) x {n}" for (b, lam), n in chosen.most_common()))


if __name__ == "__main__":
    main()
