"""How much does a recorded person's read gain from more recordings of each gesture in their context?

    python experiments/context_repetitions_read.py --data MAP.h5 --people s02 s04 ... \
        [--models models/cchp_path_shape.pt models/cchp_default.pt] [--repetitions 1 2 3 0]

A recorder session (`python -m rtcohand_drake.record`) gives one clip of each one-motion gesture; an
imported SHREC'17 person has 2-5 of each in their context (`split = train`; the importer holds the last
out). For each R in `--repetitions` (0: all), each person's context keeps only the first R recordings
of each gesture (its clip id's `gNNfN` part, in the order of their repetition number), and each of the
person's held-out clips (`split = test`, the same for every R) is read alone by each policy file,
stepped as the policy box steps it from a zero state (`analysis.context_reading.play_clip`). Prints,
per file and R, the squared error as a share of commanding zero twist, pooled over the people's clips,
the median over people, and the context's mean size in clips.

Finding: docs/real_people.md, section 6 ("Recordings of each gesture in the context").
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np


def first_repetitions(clips, repetitions: int):
    """The clips with at most `repetitions` (0: all) of each gesture, the earliest repetitions first."""
    by_gesture = defaultdict(list)
    for c in sorted(clips, key=lambda c: c.clip_id):
        by_gesture[c.clip_id[:6]].append(c)
    kept = []
    for group in by_gesture.values():
        kept += group if repetitions <= 0 else group[:repetitions]
    return kept


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.data.dataset import load_policy_clips
    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.policy_file import load_policy

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a recorded dataset (the importer's file)")
    p.add_argument("--people", nargs="+", required=True)
    p.add_argument("--models", nargs="+", default=["models/cchp_path_shape.pt", "models/cchp_default.pt"])
    p.add_argument("--repetitions", type=int, nargs="+", default=[1, 2, 3, 0], help="0: every one")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    wide = load_policy_clips(args.data, 10.0, True)
    for path in args.models:
        module = load_policy(path)
        width = int(module.feature_dim)
        for repetitions in args.repetitions:
            pooled = np.zeros(2)
            shares, sizes = [], []
            for person in args.people:
                own = [c for c in wide if c.user == person and c.labels is not None]
                context = first_repetitions([c for c in own if c.split == "train"], repetitions)
                held = [c for c in own if c.split == "test"]
                if not context or not held:
                    raise SystemExit(f"error: {args.data}: {person!r} has no labelled train and test clips")
                x_c, y_c, m = (torch.from_numpy(a) for a in pack_context(
                    [(c.features[:, :width], c.labels) for c in context]))
                keys, values, z, _ = module.encode_context(x_c, y_c, m)
                sums = np.zeros(2)
                for c in held:
                    out = play_clip(module, np.nan_to_num(c.features[:, :width]), keys, values, z)
                    y = np.nan_to_num(np.asarray(c.labels, np.float64))
                    sums += [np.sum((y - out) ** 2), np.sum(y ** 2)]
                pooled += sums
                shares.append(sums[0] / sums[1])
                sizes.append(len(context))
            label = "all" if repetitions <= 0 else str(repetitions)
            print(f"{path}: {label} per gesture: pooled {pooled[0] / pooled[1]:.4f} of zero twist, median over "
                  f"people {np.median(shares):.4f}, context {np.mean(sizes):.1f} clips", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
