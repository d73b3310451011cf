"""Can how well a ridge reads a person's own clips (cross-validated) pick the people a linear read fits?

    python experiments/ridge_switch.py --data POP.h5 [POP2.h5 ...] [--model models/cchp_default.pt]
        [--every 4] [--thresholds 0.05 0.08 0.1 0.15] [--out FILE.json]

For every `--every`-th Own episode of each file (`data.sampling.evaluation_episodes`, seed 0):
- `ridge_cv`: the per-person ridge (`learning.ridge_reference`, window 10, lambda 100) read over the
  episode's context clips by folds (clip b in fold b mod 4, each fold read with the ridge fitted on
  the others), as a share of zero twist's squared error over the same steps;
- the held-out target clip read by the ridge fitted on the whole context, and by the policy file
  stepped as the box steps it (`learning.evaluate.stepped_policy_mse`), each as squared error.

For each threshold T: the episodes with `ridge_cv` < T, and the pooled share of zero twist (the
benchmark's: mean of the episodes' MSE over the mean zero-twist MSE) when those episodes take the
ridge and the rest the file, against the file for all. A rule that picks people by `ridge_cv` alone
needs no stepping of the CCHP when the context is encoded.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FOLDS = 4


def ridge_cv_share(context, window: int, lam: float) -> float:
    from rtcohand_drake.learning.ridge_reference import RidgeReference

    err = zero = 0.0
    for fold in range(FOLDS):
        held = [p for b, p in enumerate(context) if b % FOLDS == fold]
        rest = [p for b, p in enumerate(context) if b % FOLDS != fold]
        if not held or not rest:
            continue
        ridge = RidgeReference(window, lam).fit(rest)
        for x, y in held:
            y = np.nan_to_num(np.asarray(y, np.float64))
            err += float(((ridge.predict(x) - y) ** 2).sum())
            zero += float((y ** 2).sum())
    return err / zero if zero > 0 else float("inf")


def cchp_cv_share(module, context, rows: int = 12) -> float:
    """The policy file's read of at most `rows` of the context's clips (spread over it), each stepped as
    the box steps it with the clips of the other folds as context, as a share of zero twist's error."""
    import torch

    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.data.sampling import pack_context

    picked = sorted({int(round(i)) for i in np.linspace(0, len(context) - 1, min(rows, len(context)))})
    err = zero = 0.0
    for fold in range(FOLDS):
        held = [b for b in picked if b % FOLDS == fold]
        rest = [p for b, p in enumerate(context) if b % FOLDS != fold]
        if not held or not rest:
            continue
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(rest))
        with torch.no_grad():
            keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
            for b in held:
                x, y = context[b]
                out = play_clip(module, np.nan_to_num(np.asarray(x, np.float32)), keys, values, z_mu)
                y = np.nan_to_num(np.asarray(y, np.float64))
                err += float(((out - y) ** 2).sum())
                zero += float((y ** 2).sum())
    return err / zero if zero > 0 else float("inf")


def main(argv=None) -> int:
    import torch
    from tqdm import tqdm

    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.evaluate import stepped_policy_mse
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.learning.ridge_reference import RidgeReference
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", nargs="+", required=True)
    p.add_argument("--model", default=str(ROOT / "models" / "cchp_default.pt"))
    p.add_argument("--every", type=int, default=4)
    p.add_argument("--window", type=int, default=10)
    p.add_argument("--lam", type=float, default=100.0)
    p.add_argument("--thresholds", type=float, nargs="+", default=[0.05, 0.08, 0.1, 0.15])
    p.add_argument("--ratios", type=float, nargs="*", default=[],
                   help="also pick by ridge_cv < R x the file's own cross-validated share (cchp_cv)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    module = load_policy(args.model)
    result = {"model": pathlib.Path(args.model).name, "every": args.every, "files": {}}
    for path in args.data:
        episodes = evaluation_episodes(load_clips(path, 10.0), "Own", 0)[::args.every]
        rows = []
        for e in tqdm(episodes, desc=pathlib.Path(path).name, file=sys.stderr):
            context = [(np.asarray(x), np.asarray(y)) for x, y in e.context]
            y = np.asarray(e.target.labels, np.float64)
            ridge = RidgeReference(args.window, args.lam).fit(context)
            rows.append({"user": e.target.user if hasattr(e.target, "user") else "",
                         "ridge_cv": ridge_cv_share(context, args.window, args.lam),
                         "cchp_cv": cchp_cv_share(module, context) if args.ratios else None,
                         "ridge_mse": float(np.mean((ridge.predict(e.target_features) - y) ** 2)),
                         "file_mse": stepped_policy_mse(module, [e])["mse"],
                         "zero_mse": float(np.mean(y ** 2))})
        zero = np.mean([r["zero_mse"] for r in rows])
        file_share = np.mean([r["file_mse"] for r in rows]) / zero
        ridge_share = np.mean([r["ridge_mse"] for r in rows]) / zero
        summary = {"episodes": len(rows), "file": file_share, "ridge": ridge_share, "switch": {}}
        line = f"{pathlib.Path(path).name}: {len(rows)} episodes; file {file_share:.4f}, ridge {ridge_share:.4f}"
        for t in args.thresholds:
            picked = [r["ridge_cv"] < t for r in rows]
            share = np.mean([r["ridge_mse"] if k else r["file_mse"] for r, k in zip(rows, picked)]) / zero
            summary["switch"][str(t)] = {"picked": int(sum(picked)), "share": float(share)}
            line += f"; T {t}: {sum(picked)} picked, {share:.4f}"
        for r_ in args.ratios:
            picked = [r["ridge_cv"] < r_ * r["cchp_cv"] for r in rows]
            share = np.mean([r["ridge_mse"] if k else r["file_mse"] for r, k in zip(rows, picked)]) / zero
            summary["switch"][f"ratio {r_}"] = {"picked": int(sum(picked)), "share": float(share)}
            line += f"; R {r_}: {sum(picked)} picked, {share:.4f}"
        print(line, flush=True)
        cv = np.array([r["ridge_cv"] for r in rows])
        print(f"  ridge_cv min / median / max {cv.min():.3f} / {np.median(cv):.3f} / {cv.max():.3f}", flush=True)
        result["files"][pathlib.Path(path).name] = {"summary": summary, "episodes": rows}
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
