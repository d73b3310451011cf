"""Development probe: the kernel read of the hand's path and shape, with the fingers' extension added.

    python experiments/posture_kernel_read.py --data FILE.h5 [--setting Person] [--weights 0 1 2 4]
        [--lags now all]

The natural map gives one finger's rotations and the whole hand's the same motion in two postures
(docs/real_people.md, section 4). The path-and-shape features carry the posture only as 63 of 315
coordinates about the hand's centre, which also turn as the hand turns. Each finger's extension,
|tip - wrist| / the finger's length along its bones, does not turn with the hand nor scale with it.
Per episode of the setting, this fits the kernel read (`learning.kernel_reference`, bandwidth 0.5,
lambda 0.3, as the policy file for real hands) to the context on the standardised path and shape
beside the standardised extensions weighted by w (of the hand now, or at each of the path's lags),
and prints each read's share of the zero twist's squared error.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def finger_extension(shape: np.ndarray) -> np.ndarray:
    """(T, 5 x L) extensions of path-and-shape rows (T, 63 x L): per lag, per finger (thumb first),
    |tip - wrist| over the finger's length along its bones (1: straight from the wrist)."""
    from rtcohand_drake.data.hand_features import FINGER_CHAINS

    t = shape.shape[0]
    kp = shape.reshape(t, -1, 21, 3).astype(np.float64)
    wrist = kp[:, :, 0:1, :]
    chains = kp[:, :, FINGER_CHAINS, :]  # (T, L, 5, 4, 3)
    bones = np.linalg.norm(np.diff(chains, axis=3), axis=-1).sum(-1) + np.linalg.norm(
        chains[:, :, :, 0, :] - wrist, axis=-1)
    reach = np.linalg.norm(chains[:, :, :, 3, :] - wrist, axis=-1)
    return (reach / np.maximum(bones, 1e-6)).reshape(t, -1)


def main(argv=None):
    from rtcohand_drake.data.dataset import read_dataset, to_policy_clip
    from rtcohand_drake.data.hand_features import path_shape_features
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.kernel_reference import KernelReference

    p = argparse.ArgumentParser()
    p.add_argument("--data", required=True)
    p.add_argument("--setting", default="Person")
    p.add_argument("--weights", type=float, nargs="+", default=[0.0, 1.0, 2.0, 4.0])
    p.add_argument("--lags", nargs="+", default=["now", "all"], choices=["now", "all"])
    p.add_argument("--scale", type=float, default=0.5)
    p.add_argument("--lam", type=float, default=0.3)
    args = p.parse_args(argv)
    raw = [c for c in read_dataset(args.data) if c.object_velocity is not None]
    clips = [to_policy_clip(c) for c in raw]
    shape = {c.name: path_shape_features(c.keypoints, c.fps, 10.0, c.timestamps).astype(np.float64) for c in raw}
    posture = {n: finger_extension(s) for n, s in shape.items()}
    by_id = {id(c.features): c.name for c in clips}
    episodes = evaluation_episodes(clips, args.setting, 0)
    sums: dict = {}

    def add(name, pred, y):
        e, z = sums.get(name, (0.0, 0.0))
        sums[name] = (e + np.mean((pred - y) ** 2), z + np.mean(y ** 2))

    for i, e in enumerate(episodes):
        y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
        names = [by_id[id(px)] for px, _ in e.context]
        ylab = np.concatenate([np.nan_to_num(np.asarray(py, np.float64)) for _, py in e.context])
        xk = np.concatenate([shape[n] for n in names])
        xq = shape[e.target.name]
        smean, sstd = xk.mean(0), xk.std(0) + 1e-6
        for lags in args.lags:
            cols = slice(0, 5) if lags == "now" else slice(None)
            pk = np.concatenate([posture[n][:, cols] for n in names])
            pq = posture[e.target.name][:, cols]
            pmean, pstd = pk.mean(0), pk.std(0) + 1e-6
            for w in args.weights:
                if w == 0 and lags != args.lags[0]:
                    continue
                fk = np.hstack([(xk - smean) / sstd, w * (pk - pmean) / pstd])
                fq = np.hstack([(xq - smean) / sstd, w * (pq - pmean) / pstd])
                read = KernelReference(args.scale, args.lam, start=0, standardise=False).fit([(fk, ylab)]).predict(fq)
                add("path and shape" if w == 0 else f"+ extension ({lags}) x {w:g}", read, y)
        if i % 20 == 0:
            print(f"{i + 1}/{len(episodes)}", file=sys.stderr)
    print(f"{args.data} {args.setting}: {len(episodes)} episodes; kernel read, shares of zero twist")
    for name, (e, z) in sorted(sums.items(), key=lambda kv: kv[1][0] / kv[1][1]):
        print(f"  {e / z:.3f}  {name}")


if __name__ == "__main__":
    main()
