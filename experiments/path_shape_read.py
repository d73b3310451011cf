"""Development probe: the shipped policy against a kernel read of the hand's path and shape, and blends.

    python experiments/path_shape_read.py --data FILE.h5 [--setting Person|Own] [--medians 1 3 5]

Per episode of the setting (recorded people: Person; simulated people: Own), as `evaluate` forms
them, it steps the exported policy as the policy box does (own mean fed back, z the prior mean) and
fits the kernel read to the episode's context, then prints each read's share of the zero twist's
squared error: the shipped policy's mean, its context read, the kernel read, the kernel read plus
the policy's correction (mean - read) times w, and alpha-blends of the kernel read and the mean.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch


def kernel_fit(x, y, scale=0.5, lam=0.3, standardise=True):
    """The kernel reference (`learning.kernel_reference`) on every column of x; with the velocities
    weighted in, the features arrive standardised already (`standardise` False)."""
    from rtcohand_drake.learning.kernel_reference import KernelReference

    return KernelReference(scale, lam, start=0, standardise=standardise).fit([(x, y)]).predict


def main(argv=None):
    from rtcohand_drake.data.dataset import read_dataset, to_policy_clip
    from rtcohand_drake.data.hand_features import path_shape_features
    from rtcohand_drake.data.sampling import evaluation_episodes, pack_context
    from rtcohand_drake.learning.policy_file import load_policy

    p = argparse.ArgumentParser()
    p.add_argument("--data", required=True)
    p.add_argument("--setting", default="Person")
    p.add_argument("--model", default="models/cchp_default.pt")
    p.add_argument("--medians", type=int, nargs="+", default=[1])
    p.add_argument("--scales", type=float, nargs="+", default=[0.5])
    p.add_argument("--lams", type=float, nargs="+", default=[0.3])
    p.add_argument("--vel-weights", type=float, nargs="+", default=[0.0],
                   help="weights of the standardised 36 velocities (mean of the last --vel-steps) beside the path and shape")
    p.add_argument("--vel-steps", type=int, default=1)
    p.add_argument("--lags", type=float, nargs="+", default=None, help="lags (s) of the path and shape")
    p.add_argument("--max-episodes", type=int, default=0)
    p.add_argument("--stride", type=int, default=1, help="every N-th episode")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    raw = [c for c in read_dataset(args.data) if c.object_velocity is not None]
    clips = [to_policy_clip(c) for c in raw]
    lags = {} if args.lags is None else {"lags_s": tuple(args.lags)}
    shape = {m: {c.name: path_shape_features(c.keypoints, c.fps, 10.0, c.timestamps, median=m, **lags) for c in raw}
             for m in args.medians}
    by_id = {id(c.features): c.name for c in clips}
    episodes = evaluation_episodes(clips, args.setting, 0)
    episodes = episodes[::args.stride]
    if args.max_episodes:
        episodes = episodes[:args.max_episodes]
    module = load_policy(args.model)
    H, Dz = int(module.hidden_size), int(module.latent_dim)
    sums = {}

    def add(name, pred, y):
        e, z = sums.get(name, (0.0, 0.0))
        sums[name] = (e + np.mean((pred - y) ** 2), z + np.mean(y ** 2))

    for i, e in enumerate(episodes):
        y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
        x_c, y_c, mask = pack_context(e.context)
        with torch.no_grad():
            keys, values, z_mu, _ = module.encode_context(torch.from_numpy(x_c), torch.from_numpy(y_c),
                                                         torch.from_numpy(mask))
            h, c, yp = torch.zeros(H), torch.zeros(H), torch.zeros(6)
            means, reads = [], []
            for x in np.nan_to_num(e.target_features):
                mean, _, h, c, r, _, _ = module.step_read(torch.from_numpy(x.astype(np.float32)), yp, h, c, keys,
                                                          values, z_mu)
                yp = mean
                means.append(mean.numpy()), reads.append(r.numpy().reshape(-1, 6).mean(0))
        mean, read = np.array(means, np.float64), np.array(reads, np.float64)
        add("policy mean", mean, y)
        add("policy read", read, y)
        ctx_names = [by_id[id(px)] for px, _ in e.context]
        ylab = np.concatenate([np.nan_to_num(np.asarray(py, np.float64)) for _, py in e.context])
        def vel(x):
            x = np.nan_to_num(np.asarray(x, np.float64))
            c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), 0)
            idx = np.arange(1, len(x) + 1)
            lo = np.maximum(idx - args.vel_steps, 0)
            return (c[idx] - c[lo]) / (idx - lo)[:, None]
        vc = np.concatenate([vel(px) for px, _ in e.context])
        vmean, vstd = vc.mean(0), vc.std(0) + 1e-6
        vt = vel(e.target_features)
        for m in args.medians:
          for vw in args.vel_weights:
            xk = np.concatenate([shape[m][n].astype(np.float64) for n in ctx_names])
            xq = shape[m][e.target.name].astype(np.float64)
            if vw > 0:  # standardise here; the velocities weigh vw each against the path and shape
                smean, sstd = xk.mean(0), xk.std(0) + 1e-6
                xk = np.hstack([(xk - smean) / sstd, vw * (vc - vmean) / vstd])
                xq = np.hstack([(xq - smean) / sstd, vw * (vt - vmean) / vstd])
            for s in args.scales:
                for lam in args.lams:
                    rk = kernel_fit(xk, ylab, s, lam, standardise=vw == 0)(xq)
                    tag = f"m{m} v{vw:g} s{s:g} l{lam:g}"
                    add(f"kernel {tag}", rk, y)
                    for w in (0.5, 1.0):
                        add(f"kernel {tag} + {w:g} correction", rk + w * (mean - read), y)
                    for a in (0.5, 0.75):
                        add(f"{a:g} kernel {tag} + {1 - a:g} mean", a * rk + (1 - a) * mean, y)
        if i % 20 == 0:
            print(f"{i + 1}/{len(episodes)}", file=sys.stderr)
    print(f"{args.data} {args.setting}: {len(episodes)} episodes")
    for name, (e, z) in sorted(sums.items(), key=lambda kv: kv[1][0] / kv[1][1]):
        print(f"  {e / z:.3f}  {name}")


if __name__ == "__main__":
    main()
