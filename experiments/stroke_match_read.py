"""Experiment: does reading the stroke as a whole, matched against each context clip with time warping,
read recorded people better than the kernel read of a fixed window?

    python experiments/stroke_match_read.py --data dev_natural.h5 [custom.h5 ...]
        [--velocity-weights W ...] [--parts-weights P ...] [--taus TAU ...] [--blends B ...]

Each step's frame is the hand's shape about its centre (63 values), the centre's velocity (3, each
weighted W against 1 for a shape value) and the 36 hand-part velocities (each weighted P),
standardised by the person's context. The live stream is matched to every context clip by an
open-begin, open-end time warp with steps (1,0), (1,1) and (1,2), so the stream may run up to twice
as fast as the clip, or slower. A match starts at a clip's first frame (the hand at rest) at any step
of the stream, and each clip gives the position at which its prefix matches the stream's recent
stroke best, with that match's mean cost per step. The read is the clip's labels at those positions,
weighted by exp(-(cost - best cost) / TAU) over the clips. It is blended with the kernel read of the
policy file for real hands (committed, `path_shape_policy`'s settings): B x the kernel read +
(1 - B) x the match read, the match read as it is or committed in the same way.

Per file (the Person setting's episodes, as `evaluate` forms them) it prints the share of the zero
twist's squared error of the committed kernel read, of the best settings, and of the match read
alone.
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

import numpy as np

SCALE = np.array([0.12] * 3 + [0.6] * 3)
BIG = 1e18  # a cost no path reaches


def frames(x: np.ndarray, lag_s: float) -> np.ndarray:
    """(T, 102): shape now (63), the centre's velocity over lag_s (3) and the 36 hand-part velocities,
    from features whose path and shape have lags of 0 and lag_s first."""
    now, before = x[:, 36:99], x[:, 99:162]
    vel = (now.reshape(-1, 21, 3).mean(1) - before.reshape(-1, 21, 3).mean(1)) / lag_s
    return np.hstack([now, vel, x[:, :36]])


class StrokeMatch:
    """Open-begin, open-end time warp of a live stream against each context clip (see module doc)."""

    def __init__(self, clips: list[tuple[np.ndarray, np.ndarray]], velocity_weight: float, tau: float,
                 parts_weight: float = 0.0):
        f = np.concatenate([c for c, _ in clips])
        self.mu, self.sd = f.mean(0), f.std(0) + 1e-6
        w = np.ones(f.shape[1])
        w[63:66] = velocity_weight
        w[66:] = parts_weight
        self.w = w / w.sum()
        self.pat = [((c - self.mu) / self.sd, y) for c, y in clips]
        self.tau = tau

    def read(self, stream: np.ndarray) -> np.ndarray:
        x = (stream - self.mu) / self.sd
        T = len(x)
        out = np.zeros((T, 6))
        D = [np.full(len(p), BIG) for p, _ in self.pat]
        L = [np.ones(len(p)) for p, _ in self.pat]
        for t in range(T):
            costs, reads = [], []
            for k, (p, y) in enumerate(self.pat):
                d = ((p - x[t]) ** 2) @ self.w
                prev, plen = D[k], L[k]
                cand = np.stack([np.r_[0.0, prev[:-1]],          # (1,1), or a fresh start at the clip's first frame
                                 prev,                           # (1,0)
                                 np.r_[BIG, BIG, prev[:-2]]])  # (1,2)
                clen = np.stack([np.r_[0.0, plen[:-1]], plen, np.r_[1.0, 1.0, plen[:-2]]])
                # a fresh start anywhere in the stream: the clip's first frame with no history
                cand[0, 0], clen[0, 0] = 0.0, 0.0
                mean = (cand + d) / (clen + 1)
                pick = np.argmin(mean, 0)
                cols = np.arange(len(p))
                D[k] = cand[pick, cols] + d
                L[k] = clen[pick, cols] + 1
                m = D[k] / L[k]
                j = int(np.argmin(m))
                costs.append(m[j])
                reads.append(y[j])
            costs = np.array(costs)
            wts = np.exp(-(costs - costs.min()) / self.tau)
            out[t] = (wts[:, None] * np.array(reads)).sum(0) / wts.sum()
        return np.nan_to_num(out)


def main(argv=None) -> int:
    import rtcohand_drake.data.dataset as dataset
    from rtcohand_drake.data.hand_features import path_shape_features
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.kernel_reference import KernelReference
    from rtcohand_drake.learning.train import load_clips

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from committed_read import committed

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", nargs="+", required=True)
    p.add_argument("--velocity-weights", type=float, nargs="+", default=[0.0, 5.0, 20.0])
    p.add_argument("--parts-weights", type=float, nargs="+", default=[0.0])
    p.add_argument("--velocity-lag-s", type=float, default=0.1,
                   help="the centre's velocity over this time (0.4: the path-and-shape features' first lag)")
    p.add_argument("--taus", type=float, nargs="+", default=[0.05, 0.2])
    p.add_argument("--top", type=int, default=6)
    p.add_argument("--blends", type=float, nargs="+", default=[0.0, 0.25, 0.5, 0.75, 1.0])
    args = p.parse_args(argv)
    for path in args.data:
        episodes = evaluation_episodes(load_clips(path, 10.0, path_shape=True), "Person", 0)
        original = dataset.path_shape_features
        dataset.path_shape_features = functools.partial(path_shape_features, lags_s=(0.0, args.velocity_lag_s))
        try:
            lagged = evaluation_episodes(load_clips(path, 10.0, path_shape=True), "Person", 0)
        finally:
            dataset.path_shape_features = original
        zeros, errors = [], {}
        kernels, matches = {}, {}
        for e, el in zip(episodes, lagged):
            assert e.target.name == el.target.name
            user = e.target.user
            y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
            zeros.append(np.mean(y ** 2))
            if user not in kernels:
                kernels[user] = KernelReference(0.5, 0.3, start=0).fit(
                    [(np.asarray(x)[:, 36:], np.nan_to_num(yy)) for x, yy in e.context])
                ctx = [(frames(np.asarray(x, np.float64), args.velocity_lag_s), np.nan_to_num(np.asarray(yy, np.float64)))
                       for x, yy in el.context]
                matches[user] = {(vw, tau, pw): StrokeMatch(ctx, vw, tau, pw) for vw in args.velocity_weights
                                 for tau in args.taus for pw in args.parts_weights}
            k = committed(kernels[user].predict(np.asarray(e.target_features)[:, 36:]), 0.5, 0.2, 0.6)
            errors.setdefault("kernel read, committed", []).append(np.mean((k - y) ** 2))
            stream = frames(np.asarray(el.target_features, np.float64), args.velocity_lag_s)
            for (vw, tau, pw), m in matches[user].items():
                r = m.read(stream)
                for b in args.blends:
                    name = f"match (velocity weight {vw:g}, parts {pw:g}, tau {tau:g}) blended {b:g} with the kernel's"
                    errors.setdefault(name, []).append(np.mean(((1 - b) * r + b * k - y) ** 2))
                    rc = committed(r, 0.5, 0.2, 0.6)
                    errors.setdefault(name + ", committed", []).append(np.mean(((1 - b) * rc + b * k - y) ** 2))
        shares = {name: float(np.mean(v) / np.mean(zeros)) for name, v in errors.items()}
        print(f"{path}: {len(episodes)} held-out clips; the kernel read, committed {shares['kernel read, committed']:.3f}")
        for name, value in sorted(shares.items(), key=lambda kv: kv[1])[:args.top] + [(n, v) for n, v in shares.items() if "blended 0 with" in n and "committed" not in n]:
            print(f"  {value:.3f}  {name}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
