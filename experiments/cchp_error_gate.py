"""Whom does the CCHP read? Each person's blend choice in a file that reads the hand's path and shape.

    python experiments/cchp_error_gate.py --file FILE.pt --data POP.h5 [--every 8] [--compare CCHP.pt --from 0.5]
    python experiments/cchp_error_gate.py --file FILE.pt --data MAP.h5 --people s02 s04 ...

For a generated population, every `--every`-th Own episode (`data.sampling.evaluation_episodes`,
seed 0) is encoded with its own context; for a recorded dataset, each person in `--people` is
encoded with their `split = train` clips, as the run reads them. Prints, per episode or person,
`blend_choice(keys)` of `learning.path_shape_policy`: A used, A as fitted, the share of the CCHP's
squared error the blend removes (cross-fitted), and the CCHP's own error over the person's clips as a
share of zero twist's (`--min-cchp-error` compares it), then the spread of that last figure.

With `--compare CCHP.pt --from E` (a generated population), each episode whose CCHP share is at
least E is also read, stepped as the policy box steps it, by FILE and by CCHP.pt: each one's
squared error as a share of zero twist's, and their means.

Build FILE with `--min-cchp-error 0` to see every person's choice ungated. The findings:
docs/policy.md, "One file for every hand".
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data.dataset import load_policy_clips
    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.data.sampling import evaluation_episodes, pack_context
    from rtcohand_drake.learning.evaluate import stepped_policy_mse
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.learning.path_shape_policy import encode_fitted
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--file", required=True, help="a policy file that reads the hand's path and shape")
    p.add_argument("--data", required=True)
    p.add_argument("--every", type=int, default=8)
    p.add_argument("--people", nargs="*", default=None, help="recorded people (their split = train clips)")
    p.add_argument("--compare", default=None, help="a 36-feature CCHP file to read the episodes from --from up with")
    p.add_argument("--from", dest="threshold", type=float, default=0.5)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    module = load_policy(args.file)
    if not hasattr(module, "blend_choice") or int(module.feature_dim) <= FEATURE_DIM:
        raise SystemExit(f"error: {args.file} does not read the hand's path and shape with a blend choice")

    def choice(pieces):
        x, y, m = (torch.from_numpy(a) for a in pack_context(pieces))
        return [float(v) for v in module.blend_choice(encode_fitted(module, x, y, m)[0])]

    rows = []
    if args.people:
        clips = load_policy_clips(args.data, 10.0, True)
        for person in args.people:
            pieces = [(c.features, c.labels) for c in clips
                      if c.user == person and c.split == "train" and c.labels is not None]
            if not pieces:
                raise SystemExit(f"error: {args.data}: no labelled split = train clips of {person!r}")
            rows.append((person, choice(pieces)))
            print(person, " ".join(f"{v:.3f}" for v in rows[-1][1]), flush=True)
        episodes = []
    else:
        episodes = evaluation_episodes(load_clips(args.data, 10.0, path_shape=True), "Own", 0)[::args.every]
        for i, e in enumerate(episodes):
            rows.append((i, choice(e.context)))
            print(i, " ".join(f"{v:.3f}" for v in rows[-1][1]), flush=True)
    shares = np.array([r[1][3] for r in rows])
    print(f"the CCHP's own error share over {len(rows)} contexts: min {shares.min():.3f}, median "
          f"{np.median(shares):.3f}, max {shares.max():.3f}; {int((shares >= args.threshold).sum())} at "
          f"{args.threshold} or more")
    if args.compare and episodes:
        cchp = load_policy(args.compare)
        narrow = evaluation_episodes(load_clips(args.data, 10.0), "Own", 0)[::args.every]
        reads = []
        for i, c in rows:
            if c[3] < args.threshold:
                continue
            zero = float(np.mean(np.asarray(narrow[i].target.labels, np.float64) ** 2))
            pair = (stepped_policy_mse(module, [episodes[i]])["mse"] / zero,
                    stepped_policy_mse(cchp, [narrow[i]])["mse"] / zero)
            reads.append(pair)
            print(f"episode {i}: gain {c[2]:.3f}, CCHP share {c[3]:.3f}: read {pair[0]:.4f} (file), "
                  f"{pair[1]:.4f} (CCHP)", flush=True)
        if reads:
            a = np.array(reads)
            print(f"{len(a)} episodes from {args.threshold}: mean share {a[:, 0].mean():.4f} (file), "
                  f"{a[:, 1].mean():.4f} (CCHP); the file better on {int((a[:, 0] < a[:, 1]).sum())}, "
                  f"worse on {int((a[:, 0] > a[:, 1]).sum())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
