"""Can a rule applied at each step keep the kernel read of the path and shape off the steps where it hurts?

    python experiments/kernel_step_gates.py --data POP.h5 [--every 4]
    python experiments/kernel_step_gates.py --data MAP.h5 --people s02 s04 ...

The file for real hands (`learning.path_shape_policy`, its shipped settings over `models/cchp_default.pt`)
blends its kernel read into the CCHP with one A per person. This steps the file's pieces (the CCHP's mean
and std, the kernel read with its commitment and match, and the kernel's support, the sum of its weights
over the anchors) over held-out clips, and reads each with A scaled at every step by a rule:

- `support/S`: A x min(1, support / S): the CCHP alone where no context step is near the hand;
- `std/S`: A x min(1, |the CCHP's std| / S): the CCHP alone where it is sure;
- `agree/C`: A where the two reads' cosine is over C, else 0.

The CCHP is fed its own mean, so the pieces do not depend on the rule, and each rule is read exactly
from one pass. For a generated population, every `--every`-th Own episode (seed 0) whose person gets a
kernel read (A > 0); for a recorded dataset, each named person's `split = test` clips, one by one, with
their `split = train` clips as context. Prints, per rule, the mean and pooled squared error as a share
of zero twist's and how many clips it reads better or worse than the CCHP alone. Development people
only. The findings: docs/policy.md, "Rules at each step".
"""

from __future__ import annotations

import argparse

import numpy as np


def pieces(module, context, features):
    """Per step of `features`: [support, the CCHP's mean (6), the kernel read (6), the CCHP's std (6)],
    and the person's blend choice; None where the person gets the CCHP alone."""
    import torch

    from rtcohand_drake.data.sampling import pack_context

    m = module
    x, y, mask = (torch.from_numpy(v) for v in pack_context(context))
    with torch.no_grad():
        keys, values, z, _ = m.encode_context(x, y, mask)
        choice = [float(v) for v in m.blend_choice(keys)]
        if choice[0] == 0.0:
            return choice, None
        hi, a = m.inner_hidden, m._anchors(keys.size(0))
        h, c = torch.zeros(m.hidden_size), torch.zeros(m.hidden_size)
        extras = m._extras(keys)
        fits = float(extras[m.match_extras_at + 2 * m.match_frame_dim]) > 0
        rows = []
        for xt in np.nan_to_num(np.asarray(features, np.float32)):
            xt = torch.from_numpy(xt)
            mean_i, std, h2, c2, _, _, _ = m.inner.step_read(xt[:36], h[hi:hi + 6], h[:hi], c[:hi],
                                                             m._inner_keys(keys), values, z)
            kernel = m._kernel(m._standardise(xt[36:], extras), keys, extras)
            r = torch.mm(kernel, m._anchor_part(keys, a + m.shape_dim, 6)).to(torch.float64)
            r = m._committed(r, extras[2 * m.shape_dim + 2:2 * m.shape_dim + 8]).view(6)
            if fits:
                matched, cost, length = m._match(xt[36:], h[hi + 6:], c[hi + 6:], keys, extras)
                r = (1.0 - m.match_share) * r + m.match_share * matched.to(torch.float64)
            else:
                cost = length = torch.zeros(m.match_max_steps)
            h = torch.cat([h2, mean_i, cost])
            c = torch.cat([c2, torch.zeros(6), length])
            rows.append(np.concatenate([[float(kernel.sum())], mean_i.numpy(), r.numpy(), std.view(-1).numpy()]))
        return choice, np.array(rows)


RULES = {"none": lambda p: np.ones(len(p))}
for _s in (1.0, 10.0, 100.0, 300.0):
    RULES[f"support/{_s:g}"] = (lambda s: lambda p: np.clip(p[:, 0] / s, 0.0, 1.0))(_s)
for _s in (0.05, 0.1, 0.2, 0.3):
    RULES[f"std/{_s:g}"] = (lambda s: lambda p: np.clip(np.linalg.norm(p[:, 13:19], axis=1) / s, 0.0, 1.0))(_s)
for _c in (0.0, 0.5):
    RULES[f"agree/{_c:g}"] = (lambda cmin: lambda p: ((p[:, 1:7] * p[:, 7:13]).sum(1) > cmin * np.linalg.norm(
        p[:, 1:7], axis=1) * np.linalg.norm(p[:, 7:13], axis=1)).astype(float))(_c)


def read(records, rule):
    """(mean share, the CCHP's mean share, pooled share, the CCHP's pooled share, better, worse)."""
    out = []
    for blend, p, y in records:
        a = blend * RULES[rule](p)[:, None]
        zero = np.mean(y ** 2)
        out.append((np.mean((y - a * p[:, 7:13] - (1.0 - a) * p[:, 1:7]) ** 2), np.mean((y - p[:, 1:7]) ** 2), zero))
    e = np.array(out)
    return (np.mean(e[:, 0] / e[:, 2]), np.mean(e[:, 1] / e[:, 2]), e[:, 0].sum() / e[:, 2].sum(),
            e[:, 1].sum() / e[:, 2].sum(), int((e[:, 0] < e[:, 1] - 1e-12).sum()), int((e[:, 0] > e[:, 1] + 1e-12).sum()))


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data.dataset import load_policy_clips
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning import path_shape_policy as psp
    from rtcohand_drake.learning.export import policy_and_card
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True)
    p.add_argument("--people", nargs="*", default=None, help="recorded people (their split = test clips)")
    p.add_argument("--every", type=int, default=4)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    inner, _ = policy_and_card("models/cchp_default.pt")
    module = psp.PathShapeKernelPolicy(
        inner, psp.DEFAULT_BLEND, psp.DEFAULT_BANDWIDTH, psp.DEFAULT_LAMBDA, psp.DEFAULT_CV_FOLDS, psp.DEFAULT_CV_ROWS,
        None, (psp.DEFAULT_COMMIT_SHARE, psp.COMMIT_LOW, psp.COMMIT_HIGH),
        (psp.DEFAULT_MATCH_SHARE, psp.MATCH_VELOCITY_WEIGHT, psp.MATCH_TAU), psp.DEFAULT_ANCHORS, psp.DEFAULT_MIN_GAIN,
        psp.DEFAULT_HOLD, psp.DEFAULT_MIN_CCHP_ERROR, psp.DEFAULT_MIN_BLEND).eval()
    records = []
    if args.people:
        clips = load_policy_clips(args.data, 10.0, True)
        for person in args.people:
            context = [(c.features, c.labels) for c in clips
                       if c.user == person and c.split == "train" and c.labels is not None]
            for clip in (c for c in clips if c.user == person and c.split == "test" and c.labels is not None):
                choice, steps = pieces(module, context, clip.features)
                if steps is None:
                    break
                records.append((choice[0], steps, np.asarray(clip.labels, np.float64)))
            print(f"{person}: A {choice[0]:.3f}", flush=True)
    else:
        for i, e in enumerate(evaluation_episodes(load_clips(args.data, 10.0, path_shape=True), "Own", 0)[::args.every]):
            choice, steps = pieces(module, e.context, e.target_features)
            if steps is not None:
                records.append((choice[0], steps, np.asarray(e.target.labels, np.float64)))
                print(f"episode {i}: A {choice[0]:.3f}", flush=True)
    if not records:
        raise SystemExit("error: nobody here gets a kernel read (A > 0)")
    print(f"{len(records)} clips with a kernel read; squared error as a share of zero twist's")
    print(f"{'rule':<14} {'mean':>7} {'CCHP':>7} {'pooled':>7} {'CCHP':>7} better worse")
    for rule in RULES:
        m, mc, pooled, pc, better, worse = read(records, rule)
        print(f"{rule:<14} {m:7.4f} {mc:7.4f} {pooled:7.4f} {pc:7.4f} {better:6d} {worse:5d}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
