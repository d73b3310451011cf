"""Gesture data benchmarks: generating the 15-user dataset, and feature extraction speed.

    python benchmarks/bench_data.py [--users 15] [--repeats 5] [--ratio]

Prints the generation time (simulation, then writing the file), the feature
extraction rate in keypoint frames per second (median over repeats, all
clips of the dataset), and with --ratio the context-need ratio.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

from rtcohand_drake.data.dataset import read_dataset, to_policy_clip, write_dataset
from rtcohand_drake.data.population import GeneratorConfig, context_need_ratio, generate_population
from rtcohand_drake.data.hand_features import hand_features


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--users", type=int, default=15)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--ratio", action="store_true", help="also measure the context-need ratio")
    args = parser.parse_args()

    config = GeneratorConfig()
    t0 = time.perf_counter()
    clips = generate_population(config, n_users=args.users, seed=args.seed)
    t1 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.h5")
        write_dataset(path, clips, generator=config.to_json())
        t2 = time.perf_counter()
        size_mb = os.path.getsize(path) / 1e6
        clips = read_dataset(path)
        t3 = time.perf_counter()
    print(f"generate {args.users} users, {len(clips)} clips: simulate {t1 - t0:.2f} s, "
          f"write {t2 - t1:.2f} s ({size_mb:.0f} MB), total {t2 - t0:.2f} s; read+validate {t3 - t2:.2f} s")

    frames = sum(c.num_frames for c in clips)
    rates = []
    for _ in range(args.repeats):
        s = time.perf_counter()
        for c in clips:
            hand_features(c.keypoints, c.fps, 10.0, c.timestamps)
        rates.append(frames / (time.perf_counter() - s))
    print(f"features: {frames} frames, median {statistics.median(rates):,.0f} frames/s "
          f"(min {min(rates):,.0f}, max {max(rates):,.0f}, {args.repeats} repeats)")

    if args.ratio:
        r = context_need_ratio([to_policy_clip(c) for c in clips])
        print(f"context need: pooled ridge MSE {r['pooled_mse']:.4f} / per-user ridge MSE "
              f"{r['per_user_mse']:.4f} = {r['ratio']:.2f} (predicting zero: {r['zero_mse']:.4f})")


if __name__ == "__main__":
    main()
