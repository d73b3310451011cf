"""How well a CCHP checkpoint reads out-sample users' gestures from their own clips.

    python experiments/probe_own_context.py --data out/population15.h5 --checkpoint CKPT [CKPT ...] [--clips 24]

For each out-sample user, the first `--clips` clips (file order) are predicted
free-running with the user's other clips as context (the deployed "Own"
rule), and the script prints the MSE of the mean, of the context read r(t)
(the attended twist) alone, and of commanding zero twist. A quick probe used
during development (`docs/results/README.md`); `python -m
rtcohand_drake.evaluate --settings Own` is the full evaluation.
"""

import argparse

import torch

from rtcohand_drake.learning.batching import collate
from rtcohand_drake.learning.checkpoint import load_checkpoint
from rtcohand_drake.learning.train import load_clips


def probe(model, clips, n_clips: int) -> tuple[float, float, float]:
    """(mean MSE, read MSE, zero-twist MSE) over the out-sample users' first n_clips clips."""
    sums = torch.zeros(3)
    steps = 0.0
    for user in sorted({c.user for c in clips if c.group == "out-sample"}):
        own = [c for c in clips if c.user == user and c.labels is not None]
        targets = own[:n_clips]
        batch = collate([(c.features, c.labels) for c in targets],
                        [[(o.features, o.labels) for o in own if o is not c] for c in targets])
        with torch.no_grad():
            ctx, _ = model.encode_context(batch)
            reads = []
            mean_n, _, _ = model.decode(model.normalizer_x(batch.x), ctx, ctx.z_mu, readouts=reads)
        scale = model.normalizer.label_scale
        r = torch.stack(reads, 1)
        r = (r[:, :, 0] if r.shape[2] == 1 else torch.diagonal(r, dim1=2, dim2=3)) * scale
        m = batch.mask.to(r.dtype)
        for i, pred in enumerate((mean_n * scale, r, torch.zeros_like(r))):
            sums[i] += float((((pred - batch.y) ** 2).mean(-1) * m).sum())
        steps += float(m.sum())
    mse = sums / steps
    return float(mse[0]), float(mse[1]), float(mse[2])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="out/population15.h5")
    p.add_argument("--checkpoint", nargs="+", required=True)
    p.add_argument("--clips", type=int, default=24, help="target clips per out-sample user")
    args = p.parse_args()
    torch.set_num_threads(1)
    clips = load_clips(args.data, 10.0)
    print("| checkpoint | step | mean MSE | read MSE | zero twist |")
    print("|---|---|---|---|---|")
    for path in args.checkpoint:
        model, payload = load_checkpoint(path)
        mean, read, zero = probe(model, clips, args.clips)
        print(f"| {path} | {payload.get('step')} | {mean:.4f} ({mean / zero:.2f}x) | {read:.4f} ({read / zero:.2f}x) | {zero:.4f} |")


if __name__ == "__main__":
    main()
