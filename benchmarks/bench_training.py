"""Training speed: steps/s and target clips (samples)/s of a short timed run, and
the figures recorded in a finished checkpoint.

    python benchmarks/bench_training.py --data PATH.h5 [--model cchp] [--steps 50] [--threads 1 2]
    python benchmarks/bench_training.py --checkpoint models/checkpoints/cchp_default.ckpt

A timed run trains for --steps steps (batch 32) from scratch for each thread
count, after 3 warm-up steps, and reports seconds per step, samples per second
and the projected time of the paper's 738 epochs over the training clips.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np
import torch

from rtcohand_drake.learning.checkpoint import build_model, read_checkpoint
from rtcohand_drake.learning.train import TrainConfig, data_scales, load_clips, make_batch, training_clips

PAPER_EPOCHS = 738


def timed_run(data: str, model_kind: str, steps: int, threads: int) -> dict:
    torch.set_num_threads(threads)
    cfg = TrainConfig(model=model_kind, steps=steps)
    clips = load_clips(data, cfg.rate_hz)
    train = training_clips(clips, data)
    model = build_model(model_kind)
    model.normalizer.set_scales(*data_scales(train))
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    rng = np.random.default_rng(0)
    gen = torch.Generator().manual_seed(0)
    times = []
    for step in range(steps + 3):
        t0 = time.perf_counter()
        idx = rng.choice(len(train), size=cfg.batch_size, replace=False)
        batch = make_batch([train[i] for i in idx], train, rng, cfg)
        terms = model(batch, p_tf=cfg.p_tf(step), generator=gen, x_noise_std=cfg.x_noise_std)
        opt.zero_grad()
        terms["loss"].backward()
        opt.step()
        if step >= 3:
            times.append(time.perf_counter() - t0)
    s = float(np.mean(times))
    steps_per_epoch = len(train) / cfg.batch_size
    return {"model": model_kind, "threads": threads, "s_per_step": s, "samples_per_s": cfg.batch_size / s,
            "train_clips": len(train), "paper_protocol_h": PAPER_EPOCHS * steps_per_epoch * s / 3600}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data")
    p.add_argument("--checkpoint", nargs="*", default=[])
    p.add_argument("--model", default="cchp")
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--out", default=None, help="JSON file for the results")
    args = p.parse_args()
    results = {"timed": [], "checkpoints": []}
    if args.data:
        for th in args.threads:
            r = timed_run(args.data, args.model, args.steps, th)
            results["timed"].append(r)
            print(f"{r['model']} threads={th}: {r['s_per_step'] * 1e3:.0f} ms/step, {r['samples_per_s']:.0f} samples/s, "
                  f"738 epochs over {r['train_clips']} clips would take {r['paper_protocol_h']:.2f} h")
    for ck in args.checkpoint:
        payload = read_checkpoint(ck)
        meta = payload.get("meta", {})
        r = {"checkpoint": ck, "kind": payload["kind"], "steps": payload.get("step"), **meta}
        results["checkpoints"].append(r)
        print(f"{ck}: {payload['kind']} {payload.get('step')} steps in {meta.get('train_time_s', float('nan')) / 60:.1f} min, "
              f"{meta.get('samples_per_s', float('nan')):.0f} samples/s, world size {meta.get('world_size')}, "
              f"threads {meta.get('threads')}")
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
