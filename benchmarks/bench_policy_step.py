"""Latency of the exported policy's `step` against context length, beside an exact GP.

    python benchmarks/bench_policy_step.py [--model models/cchp_default.pt] [--out docs/results]
        [--hand real|simulated]

One CPU thread (as the Drake policy system runs it). For each context length K
the context is encoded once with `encode_context`, then `step` (which also
returns the K-long attention) and `step_read` (the same step without it, what
the policy box runs each period; docs/interfaces.md) are each timed --steps
times after a warm-up, back to back; p50/p99 are reported. The exact Gaussian-process
regressor (RBF kernel on the 36 features, one output per motion dimension,
float64) is timed on the same K: conditioning on the context (Cholesky,
O(K^3)) and one prediction with its variance (O(K^2)), which is the scaling the
paper argues against. Writes step_latency.json and step_latency.png.

For a file that reads the hand's path and shape, `--hand real` (the default)
turns the context's palm as fast as a real hand's, so that the file uses its
kernel read and the time is that of its full step; `--hand simulated` leaves
it slow, as a simulated person's, so that the fast-turn gate turns the
context away and the time is that of the CCHP alone inside the file (its
encoding included).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np
import torch

REPO = pathlib.Path(__file__).resolve().parents[1]


def percentile_ms(times):
    a = np.asarray(times) * 1e3
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean())}


def load_or_build(path: pathlib.Path):
    if path.is_file():
        from rtcohand_drake.repo_paths import repo_relative

        return torch.jit.load(str(path)), repo_relative(path)  # the results file is committed
    from rtcohand_drake.learning.export import script_policy
    from rtcohand_drake.learning.nets.cchp import Cchp

    return script_policy(Cchp().eval()), "untrained default-size CCHP (no shipped model found)"


def bench_step(policy, k: int, steps: int, warmup: int, rng: np.random.Generator, real_hand: bool = True):
    piece = 50  # 5 s clips at 10 Hz
    b = int(np.ceil(k / piece))
    f = int(policy.feature_dim)  # 36, or 351 for a file that reads the hand's path and shape
    x_c = torch.from_numpy(rng.normal(size=(b, piece, f)).astype(np.float32) * 0.2)
    # Labels that the last 6 features tell (the hand's path and shape, for a file that reads them) and no
    # file learned, and a palm that turns fast (features 3-5, about 2 rad/s a step, as a real hand's does):
    # a file that blends in a read of the person's own clips then uses it (A > 0), as for a recorded
    # person, and the time is that of its full step.
    if f > 36 and real_hand:
        x_c[:, :, 3:6] *= 10.0
    y_c = 0.1 * torch.tanh(5.0 * x_c[:, :, -6:])
    mask = torch.zeros(b, piece, dtype=torch.bool)
    mask.view(-1)[:k] = True
    t0 = time.perf_counter()
    keys, values, z_mu, z_sigma = policy.encode_context(x_c, y_c, mask)
    encode_s = time.perf_counter() - t0
    xs = torch.from_numpy(rng.normal(size=(steps + warmup, f)).astype(np.float32) * 0.2)
    result = {"K": k, "encode_context_s": encode_s}
    if hasattr(policy, "blend_choice"):  # the blend of the file's own read it chose for this context
        result["blend_choice"] = [float(v) for v in policy.blend_choice(keys)]
    methods = [("step", policy.step)] + ([("step_read", policy.step_read)] if hasattr(policy, "step_read") else [])
    for name, method in methods:
        h = torch.zeros(policy.hidden_size)
        c = torch.zeros(policy.hidden_size)
        y = torch.zeros(6)
        times = []
        for i in range(steps + warmup):
            t = time.perf_counter()
            out = method(xs[i], y, h, c, keys, values, z_mu)
            dt = time.perf_counter() - t
            y, h, c = out[0], out[2], out[3]
            if i >= warmup:
                times.append(dt)
        stats = percentile_ms(times)
        if name == "step":
            result.update(stats)
        else:
            result[name] = stats
    return result


def bench_gp(k: int, predictions: int, rng: np.random.Generator):
    x = torch.from_numpy(rng.normal(size=(k, 36)) * 0.2)
    y = torch.from_numpy(rng.normal(size=(k, 6)) * 0.1)
    lengthscale, noise = 1.0, 1e-2

    def kern(a, b):
        return torch.exp(-0.5 * torch.cdist(a, b).pow(2) / lengthscale**2)

    t0 = time.perf_counter()
    chol = torch.linalg.cholesky(kern(x, x) + noise * torch.eye(k, dtype=x.dtype))
    alpha = torch.cholesky_solve(y, chol)
    condition_s = time.perf_counter() - t0
    times = []
    for _ in range(predictions):
        xs = torch.from_numpy(rng.normal(size=(1, 36)) * 0.2)
        t = time.perf_counter()
        ks = kern(xs, x)  # (1, K)
        mean = ks @ alpha
        v = torch.linalg.solve_triangular(chol, ks.t(), upper=False)
        var = 1.0 + noise - (v * v).sum(0)
        times.append(time.perf_counter() - t)
    return {"K": k, "condition_s": condition_s, **percentile_ms(times)}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", default=str(REPO / "models" / "cchp_default.pt"))
    p.add_argument("--out", default=str(REPO / "docs" / "results"))
    p.add_argument("--lengths", type=int, nargs="+", default=[150, 500, 1000, 2000, 5000, 10000])
    p.add_argument("--gp-lengths", type=int, nargs="+", default=[150, 500, 1000, 2000, 5000])
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--warmup", type=int, default=300)
    p.add_argument("--hand", choices=["real", "simulated"], default="real",
                   help="a file that reads the path and shape: a context whose palm turns fast (its kernel read "
                        "on) or slowly (the CCHP alone)")
    args = p.parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    if args.model != p.get_default("model") and not pathlib.Path(args.model).is_file():
        p.error(f"--model {args.model}: no such file")  # an untrained stand-in only when nothing is shipped yet
    policy, source = load_or_build(pathlib.Path(args.model))
    cchp = []
    for k in args.lengths:
        r = bench_step(policy, k, args.steps, args.warmup, rng, args.hand == "real")
        cchp.append(r)
        print(f"CCHP step   K={k:6d}: p50 {r['p50']:.3f} ms  p99 {r['p99']:.3f} ms  (encode_context {r['encode_context_s']:.2f} s)")
        if "step_read" in r:
            print(f"  step_read K={k:6d}: p50 {r['step_read']['p50']:.3f} ms  p99 {r['step_read']['p99']:.3f} ms")
        if "blend_choice" in r:
            print(f"  blend     K={k:6d}: A {r['blend_choice'][0]:.3f} (the file's own read's share of its output)")
    gp = []
    for k in args.gp_lengths:
        r = bench_gp(k, 200, rng)
        gp.append(r)
        print(f"exact GP    K={k:6d}: predict p50 {r['p50']:.3f} ms  p99 {r['p99']:.3f} ms  condition {r['condition_s']:.2f} s")
    result = {"model": source, "hand": args.hand, "threads": 1, "torch": str(torch.__version__), "cchp": cchp, "exact_gp": gp}
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "step_latency.json").write_text(json.dumps(result, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.3))
    ks = [r["K"] for r in cchp]
    axes[0].plot(ks, [r["p50"] for r in cchp], "o-", label="CCHP step p50")
    axes[0].plot(ks, [r["p99"] for r in cchp], "s--", label="CCHP step p99")
    if all("step_read" in r for r in cchp):
        axes[0].plot(ks, [r["step_read"]["p50"] for r in cchp], "o-", label="CCHP step_read p50")
        axes[0].plot(ks, [r["step_read"]["p99"] for r in cchp], "s--", label="CCHP step_read p99")
    axes[0].plot([r["K"] for r in gp], [r["p50"] for r in gp], "^-", label="exact GP predict (mean+var) p50")
    axes[0].axhline(1.0, color="gray", lw=0.8, ls=":")
    axes[0].set_xscale("log")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("context steps K")
    axes[0].set_ylabel("ms per step (1 thread)")
    axes[0].legend(fontsize=7)
    axes[1].plot(ks, [r["encode_context_s"] for r in cchp], "o-", label="CCHP encode_context")
    axes[1].plot([r["K"] for r in gp], [r["condition_s"] for r in gp], "^-", label="exact GP Cholesky")
    axes[1].set_xscale("log")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("context steps K")
    axes[1].set_ylabel("s per new context")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "step_latency.png", dpi=90)
    print(f"wrote {out / 'step_latency.json'} and {out / 'step_latency.png'}")


if __name__ == "__main__":
    main()
