"""Which gestures no linear read sees, and whether a signed-square feature (x |x|) lets it see them.

    python experiments/probe_signed_square.py --population-seeds 0 3 4 5 6 7 8 \
        [--reports shipped=out/report/report.json signed_square=out/other/report.json]

A finger sweep whose sign is carried by which stroke is fast (out fast, back
slowly) moves the hand parts back and forth: over a window, its frames sum to
about zero whatever the sign, so a linear function of them cannot read it. The
sum of x |x| over the window keeps the fast stroke's sign.

For the five out-sample people of each population (development seeds only):

- the fitted-to-the-person ridge (`learning.ridge_reference`: the last 10
  frames of the 36 features, lambda 100 on standardised inputs), and the same
  ridge with the window's sum of x |x| (36 more inputs): Own error (each clip
  held out in six folds, as a share of commanding zero twist) and the motions
  read below 0.3 (median reading gain over the person's clips);
- with `--reports`, `report.json` files of `benchmarks/report_populations.py`
  for policy files on the same populations: their motions read below 0.3,
  counted by the kind of gesture the person uses for them.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np

from rtcohand_drake.analysis.context_reading import (
    builtin_clips,
    held_out_readings,
    motion_table,
)
from rtcohand_drake.data.population import GeneratorConfig, simulate_user
from rtcohand_drake.learning.ridge_reference import windows

OUT_SAMPLE = ("u10", "u11", "u12", "u13", "u14")
DIMENSIONS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
POOR = 0.3


def design(x: np.ndarray, signed_square: bool, window: int = 10) -> np.ndarray:
    w = windows(x, window)
    if not signed_square:
        return w
    x = np.nan_to_num(np.asarray(x, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    sq = windows(x * np.abs(x), window).reshape(len(x), window, -1).sum(1)
    return np.concatenate([w, sq], 1)


def ridge_means(clips, signed_square: bool, lam: float = 100.0, folds: int = 6) -> list[np.ndarray]:
    """The ridge of `learning.ridge_reference` on `design`'s inputs, held out in `folds` folds."""
    means: list = [None] * len(clips)
    for f in range(folds):
        fit = [c for i, c in enumerate(clips) if i % folds != f]
        X = np.concatenate([design(c.features, signed_square) for c in fit])
        Y = np.concatenate([np.nan_to_num(c.labels) for c in fit])
        mu, sd, ym = X.mean(0), np.maximum(X.std(0), 1e-6), Y.mean(0)
        Xs = (X - mu) / sd
        W = np.linalg.solve(Xs.T @ Xs + lam * np.eye(X.shape[1]), Xs.T @ (Y - ym))
        for i in range(f, len(clips), folds):
            means[i] = (design(clips[i].features, signed_square) - mu) / sd @ W + ym
    return means


def gesture_kind(user, motion: str) -> str:
    g = user.gestures[(DIMENSIONS.index(motion[:2]), 1 if motion[2] == "+" else -1)]
    return g.kind + (f" ({g.pattern})" if g.pattern else "")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--population-seeds", type=int, nargs="+", required=True)
    p.add_argument("--reports", nargs="*", default=[], help="NAME=report.json of benchmarks/report_populations.py (a NAME may repeat: "
                        "its populations are merged)")
    args = p.parse_args(argv)
    if any(s >= 100 for s in args.population_seeds):
        p.error("a probe for choosing: use development populations (seeds 0-99)")
    reports = {}
    for item in args.reports:
        name, _, path = item.partition("=")
        reports.setdefault(name, {}).update(json.loads(Path(path).read_text())["populations"])
    config = GeneratorConfig()
    totals = {"ridge": Counter(), "ridge + signed square": Counter(), **{n: Counter() for n in reports}}
    own = {"ridge": [], "ridge + signed square": []}
    print("| population | person | Own, ridge | Own, ridge + signed square | motions below 0.3: ridge | ridge + signed square |"
          + "".join(f" {n} |" for n in reports))
    print("|---|---|---|---|---|---|" + "---|" * len(reports))
    for seed in args.population_seeds:
        for i, user_id in enumerate(OUT_SAMPLE):
            user, _, _ = simulate_user(config, 10 + i, "out-sample", seed)
            clips = builtin_clips(user_id, 10.0, seed)
            zero = sum(float((c.labels ** 2).sum()) for c in clips)
            cells = []
            for name, sq in (("ridge", False), ("ridge + signed square", True)):
                means = ridge_means(clips, sq)
                own[name].append(sum(float(((m - c.labels) ** 2).sum()) for m, c in zip(means, clips)) / zero)
                poor = [m for m, _, g, _ in motion_table(held_out_readings(None, clips, means=means)) if g < POOR]
                totals[name].update(gesture_kind(user, m) for m in poor)
                cells.append(poor)
            for name, pops in reports.items():
                gains = pops.get(str(seed), {}).get("people", {}).get(user_id, {}).get("gains", {})
                poor = [m for m, g in gains.items() if g < POOR]
                totals[name].update(gesture_kind(user, m) for m in poor)
                cells.append(poor)
            print(f"| {seed} | {user_id} | {own['ridge'][-1]:.3f} | {own['ridge + signed square'][-1]:.3f} | "
                  + " | ".join(", ".join(c) or "-" for c in cells) + " |", flush=True)
    print()
    for name, values in own.items():
        print(f"mean Own, {name}: {np.mean(values):.3f}")
    print("\nmotions read below 0.3, by the gesture the person makes for them:")
    for name, counts in totals.items():
        print(f"  {name}: {sum(counts.values())} ({', '.join(f'{k} {v}' for k, v in counts.most_common())})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
