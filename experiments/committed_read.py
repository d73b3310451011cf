"""Experiment: does a kernel read that commits to one command read recorded people better?

    python experiments/committed_read.py --data dev_natural.h5 [custom.h5 ...] [--encoder ENCODER.pt]

Later in a gesture the kernel read of the hand's path and shape (`learning.kernel_reference`) mostly
points the right way, at about half the command's size: it averages over context steps of several
gestures. Scaling it up does not help (the misreads grow with it). Here each step's read is instead
blended with its dominant command: the axis largest as a share of the context's command size on it
(`SCALE`, the labels of `data.import_shrec17`), at full size once the read reaches HIGH of that size,
scaled down linearly to none at LOW; the output is SHARE x that command + (1 - SHARE) x the read.
For each file (the Person setting's episodes, as `evaluate` forms them) it prints the share of the zero
twist's squared error of the read and of the best settings of the grid. `--encoder` reads the kernel
over a `learning.hand_encoder` embedding instead of the raw features.
"""

from __future__ import annotations

import argparse

import numpy as np

SCALE = np.array([0.12] * 3 + [0.6] * 3)  # the recorded people's command sizes (data.import_shrec17)


def committed(p: np.ndarray, share: float, low: float, high: float) -> np.ndarray:
    """The reads (T, 6), share of each replaced by its dominant command (as `path_shape_policy` commits)."""
    s = p / SCALE
    rows = np.arange(len(s))
    axis = np.argmax(np.abs(s), 1)
    sure = np.clip((np.abs(s[rows, axis]) - low) / (high - low), 0.0, 1.0)
    command = np.zeros_like(p)
    command[rows, axis] = sure * np.sign(s[rows, axis]) * SCALE[axis]
    return share * command + (1.0 - share) * p


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.kernel_reference import KernelReference
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", nargs="+", required=True)
    p.add_argument("--encoder", default=None)
    p.add_argument("--shares", type=float, nargs="+", default=[0.5, 1.0])
    p.add_argument("--lows", type=float, nargs="+", default=[0.1, 0.2, 0.3, 0.4])
    p.add_argument("--highs", type=float, nargs="+", default=[0.3, 0.4, 0.5, 0.6, 0.8])
    p.add_argument("--top", type=int, default=8)
    args = p.parse_args(argv)
    embed = lambda x: x  # noqa: E731
    if args.encoder:
        from rtcohand_drake.learning.hand_encoder import load_encoder

        encoder = load_encoder(args.encoder)[0]

        def embed(x):
            with torch.no_grad():
                return encoder(torch.from_numpy(np.asarray(x, np.float32))).numpy().astype(np.float64)

    grid = [(s, lo, hi) for s in args.shares for lo in args.lows for hi in args.highs if hi > lo]
    for path in args.data:
        episodes = evaluation_episodes(load_clips(path, 10.0, path_shape=True), "Person", 0)
        fits, errors, zeros = {}, {}, []
        for e in episodes:
            user = e.target.user
            if user not in fits:
                fits[user] = KernelReference(0.5, 0.3, start=0).fit(
                    [(embed(np.asarray(x)[:, 36:]), np.nan_to_num(y)) for x, y in e.context])
            y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
            read = fits[user].predict(embed(np.asarray(e.target_features)[:, 36:]))
            zeros.append(np.mean(y ** 2))
            errors.setdefault("the kernel read", []).append(np.mean((read - y) ** 2))
            for share, low, high in grid:
                errors.setdefault(f"committed: share {share:g}, from {low:g} to {high:g}", []).append(
                    np.mean((committed(read, share, low, high) - y) ** 2))
        shares = {name: float(np.mean(v) / np.mean(zeros)) for name, v in errors.items()}
        print(f"{path}: {len(episodes)} held-out clips; the kernel read {shares['the kernel read']:.3f}")
        for name, value in sorted(shares.items(), key=lambda kv: kv[1])[:args.top]:
            print(f"  {value:.3f}  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
