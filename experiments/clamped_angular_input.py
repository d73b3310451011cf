"""Do recorded hands' fast-turning hand parts spoil the CCHP's read? The read with each part's angular velocity clamped.

    python experiments/clamped_angular_input.py --data MAP.h5 --model models/cchp_default.pt \
        --people s02 s04 ... [--limits 0 20 10 6 3]

Recorded hands turn their parts far faster than simulated ones: a finger's frame turns faster than
10 rad/s on 10-15 % of the 10 development people's policy steps (simulated populations: 0.2-0.6 %),
the palm faster than 5 rad/s on 6-7 % (simulated: none). Many are tracking, not motion (a finger
frame's half turn, a glitch of the skeleton). For each limit L (0: none), every part's angular
velocity (3-vector) longer than L rad/s is scaled down to L, in the context and in the clips read,
and each person's `split = test` clips are read one by one by the exported 36-feature CCHP with
their `split = train` clips as context, as the policy box steps it. Prints the squared error as a
share of zero twist's, pooled over the people's clips, and its median over people.

Finding: docs/real_people.md, section 6 ("The CCHP's input with its angular velocities clamped").
"""

from __future__ import annotations

import argparse

import numpy as np


def clamp_angular(x: np.ndarray, limit: float) -> np.ndarray:
    """(T, >= 36) features with each hand part's angular velocity no longer than `limit` (0: as given)."""
    x = np.array(x, np.float32, copy=True)
    if limit <= 0:
        return x
    parts = x[:, :36].reshape(-1, 6, 6)
    w = parts[:, :, 3:]
    norm = np.linalg.norm(w, axis=2, keepdims=True)
    parts[:, :, 3:] = w * np.minimum(1.0, limit / np.maximum(norm, 1e-9))
    x[:, :36] = parts.reshape(-1, 36)
    return x


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.data.dataset import load_policy_clips
    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.policy_file import load_policy

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a recorded dataset (the importer's file)")
    p.add_argument("--model", default="models/cchp_default.pt", help="an exported 36-feature CCHP file")
    p.add_argument("--people", nargs="+", required=True)
    p.add_argument("--limits", type=float, nargs="+", default=[0, 20, 10, 6, 3], help="rad/s; 0: no clamp")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    module = load_policy(args.model)
    if int(module.feature_dim) != FEATURE_DIM:
        raise SystemExit(f"error: {args.model} does not read the 36 hand-part velocities alone")
    clips = load_policy_clips(args.data, 10.0)
    people = []
    for person in args.people:
        own = [c for c in clips if c.user == person and c.labels is not None]
        context = [(c.features, c.labels) for c in own if c.split == "train"]
        held = [(c.features, c.labels) for c in own if c.split == "test"]
        if not context or not held:
            raise SystemExit(f"error: {args.data}: {person!r} has no labelled train and test clips")
        people.append((person, context, held))
    for limit in args.limits:
        pooled = np.zeros(2)
        shares = []
        for person, context, held in people:
            x_c, y_c, m = (torch.from_numpy(a) for a in pack_context([(clamp_angular(x, limit), y) for x, y in context]))
            keys, values, z, _ = module.encode_context(x_c, y_c, m)
            sums = np.zeros(2)
            for x, y in held:
                out = play_clip(module, np.nan_to_num(clamp_angular(x, limit)), keys, values, z)
                y = np.nan_to_num(np.asarray(y, np.float64))
                sums += [np.sum((y - out) ** 2), np.sum(y ** 2)]
            pooled += sums
            shares.append(sums[0] / sums[1])
        label = f"{limit:g} rad/s" if limit > 0 else "none"
        print(f"clamp {label}: pooled {pooled[0] / pooled[1]:.4f} of zero twist, median over people "
              f"{np.median(shares):.4f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
