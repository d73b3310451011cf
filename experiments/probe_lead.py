"""Does shifting the context's labels earlier make the command lead the handler's lag?

    python experiments/probe_lead.py --data out/population15_s0.h5 [--users u10 u11 u12 u13 u14] [--leads 0 2 4 8]

The handler's labels start 150-350 ms after the gesture and then ramp up. A
lead of k policy steps pairs each context gesture frame with the label k
steps later (the clip's first T - k frames with its last T - k labels), so
the closed-form read is solved for what the person will want, not what the
handler had reached. For each out-sample user and lead, every clip is played
through the shipped policy with the user's other clips as context (six
folds, held out) and the script prints: the held-out error against the real
(lagged) labels, relative to zero twist; and, on the single-motion clips, the
median time from the gesture's start (hand features above 10 % of the clip's
peak) to the labels' and to the policy output's 20 % of their own peaks, and
to the hand features' 50 %. The estimate of each user's delay by the
cross-correlation of gesture speed and label speed (0-1 s) is printed beside.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from rtcohand_drake.analysis.context_reading import clips_from_file, held_out_means
from rtcohand_drake.learning.policy_file import load_policy

FULL_SCALE = np.array([0.25, 0.25, 0.25, 1.0, 1.0, 1.0])  # m/s and rad/s: twists on a common scale


def delay_estimate(clips, max_lag: int = 10) -> int:
    """The lag (steps) maximising the correlation of gesture speed with the later label speed."""
    acc = np.zeros(max_lag + 1)
    for c in clips:
        g = np.linalg.norm(c.features, axis=1)
        y = np.linalg.norm(c.labels / FULL_SCALE, axis=1)
        g, y = g - g.mean(), y - y.mean()
        for k in range(min(max_lag, len(g) - 1) + 1):
            acc[k] += float(np.dot(g[: len(g) - k], y[k:]))
    return int(np.argmax(acc))


def onsets(clip, out: np.ndarray, rate_hz: float = 10.0):
    """(label 20 %, output 20 %, features 50 %) after the gesture start, s (None where never)."""
    d = clip.active_dims[0]
    sign = np.sign(clip.labels[np.argmax(np.abs(clip.labels[:, d])), d])
    strength = np.linalg.norm(clip.features, axis=1)
    t0 = int(np.argmax(strength > 0.1 * strength.max()))
    steps = np.arange(len(strength))

    def first(a, share):
        if a.max() <= 1e-6:
            return None
        hit = np.flatnonzero((a > share * a.max()) & (steps >= t0))
        return (hit[0] - t0) / rate_hz if len(hit) else None

    return first(sign * clip.labels[:, d], 0.2), first(sign * out[:, d], 0.2), first(strength, 0.5)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True)
    p.add_argument("--model", default="models/cchp_default.pt")
    p.add_argument("--users", nargs="+", default=["u10", "u11", "u12", "u13", "u14"])
    p.add_argument("--leads", type=int, nargs="+", default=[0, 2, 4, 8])
    args = p.parse_args()
    torch.set_num_threads(1)
    module = load_policy(args.model)
    print("| user | delay estimate | lead | error / zero twist | label 20 % | output 20 % | features 50 % |")
    print("|---|---|---|---|---|---|---|")
    for user in args.users:
        clips, _ = clips_from_file(args.data, user, 10.0)
        zero = np.mean([np.mean(c.labels ** 2) for c in clips])
        delay = delay_estimate(clips)
        for lead in args.leads:
            means = held_out_means(module, clips, lead=lead)
            err = np.mean([np.mean((m - c.labels) ** 2) for m, c in zip(means, clips)]) / zero
            ons = [onsets(c, m) for c, m in zip(clips, means) if len(c.active_dims) == 1]
            med = [np.median([o[k] for o in ons if o[k] is not None]) * 1e3 for k in range(3)]
            print(f"| {user} | {delay * 100} ms | {lead * 100} ms | {err:.3f} | {med[0]:.0f} ms | {med[1]:.0f} ms "
                  f"| {med[2]:.0f} ms |", flush=True)


if __name__ == "__main__":
    main()
