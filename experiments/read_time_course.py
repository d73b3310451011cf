"""Where in a gesture the read's error lies: by time since the gesture's label began, and per gesture.

    python experiments/read_time_course.py --logs DIR/*.h5 [--out FILE.json]

Reads run logs of replays of labelled clips (`run --gesture-source replay --clip PERSON --split test
--log LOG.h5`), each label paired with the policy box's read of its frame
(`analysis.replay_read.paired`). A gesture is a run of steps whose label is not zero.

- **Time course**: the squared error and the labels' squared size (what commanding zero twist
  would cost) in bins of time since the gesture's label began, and after it ended (the rest).
  The share of each bin's error in the whole error tells whether the read loses most while it
  cannot yet tell the gesture (its first steps) or throughout.
- **A read that knows the gesture after tau**: zero twist until tau seconds into each gesture,
  then the label exactly, and zero at rest. Its share of zero twist's error is the least any
  read can reach that needs tau of the gesture to tell it; it bounds the goals from below.
- **Per gesture**: the direction of the read summed over the gesture (its dominant axis and
  sign, as a share of a full command) against the label's: right, another axis, or reversed;
  and the read's size along the right axis over the label's (the gain) for the gestures read
  in the right direction.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

BINS_S = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.5, 2.0, np.inf)
TAUS_S = (0.0, 0.1, 0.2, 0.3, 0.5)


def gestures(labels: np.ndarray) -> list[tuple[int, int]]:
    """[(first step, one past the last)] of each run of non-zero labels."""
    on = np.abs(labels).max(1) > 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
    return list(zip(edges[0::2], edges[1::2]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--logs", nargs="+", required=True)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    from rtcohand_drake.analysis.gesture_following import FULL_COMMAND as FULL
    from rtcohand_drake.analysis.replay_read import paired
    from rtcohand_drake.run_log import read_run_log

    err_bins, zero_bins = np.zeros(len(BINS_S)), np.zeros(len(BINS_S))  # the last: after the label
    oracle = {tau: 0.0 for tau in TAUS_S}
    total_err = total_zero = 0.0
    verdicts = {"right": 0, "other axis": 0, "reversed": 0}
    gains = []
    for path in args.logs:
        pairs = paired(read_run_log(path))
        if pairs is None:
            raise SystemExit(f"{path}: no labels of replayed clips in this log")
        out, labels, rate = pairs
        e = ((out - labels) ** 2).sum(1)
        z = (labels ** 2).sum(1)
        total_err += e.sum()
        total_zero += z.sum()
        since = np.full(len(labels), -1.0)
        for a, b in gestures(labels):
            since[a:b] = np.arange(b - a) / rate
            summed = (out[a:b] / FULL).sum(0)
            wanted = (labels[a:b] / FULL).sum(0)
            axis = int(np.abs(wanted).argmax())
            got = int(np.abs(summed).argmax())
            if got != axis:
                verdicts["other axis"] += 1
            elif np.sign(summed[got]) != np.sign(wanted[axis]):
                verdicts["reversed"] += 1
            else:
                verdicts["right"] += 1
                gains.append(float(summed[axis] / wanted[axis]))
        gesture = since >= 0
        idx = np.searchsorted(BINS_S, since[gesture], side="right") - 1
        np.add.at(err_bins, idx, e[gesture])
        np.add.at(zero_bins, idx, z[gesture])
        err_bins[-1] += e[~gesture].sum()
        zero_bins[-1] += z[~gesture].sum()
        for tau in TAUS_S:  # zero before tau into the gesture, the label after
            oracle[tau] += float(z[gesture & (since < tau - 1e-9)].sum())
    share = total_err / total_zero
    names = [f"{BINS_S[i]:.1f}-{BINS_S[i + 1]:.1f} s" for i in range(len(BINS_S) - 2)] + [
        f">= {BINS_S[-2]:.1f} s", "rest (no label)"]
    print(f"{len(args.logs)} runs: the read's share of zero twist {share:.3f}")
    print("| time since the label began | share of the read's error | the read's error over zero twist's there |")
    print("|---|---|---|")
    for name, e, z in zip(names, err_bins, zero_bins):
        print(f"| {name} | {e / total_err:.2f} | {e / z:.2f} |" if z > 0 else f"| {name} | {e / total_err:.2f} | - |")
    print("a read that knows the gesture after tau: " + ", ".join(
        f"tau {tau:.1f} s: {oracle[tau] / total_zero:.3f}" for tau in TAUS_S))
    n = sum(verdicts.values())
    print(f"{n} gestures: direction right {verdicts['right']} ({verdicts['right'] / n:.0%}), another axis "
          f"{verdicts['other axis']}, reversed {verdicts['reversed']}; gain along the right axis, median "
          f"{np.median(gains):.2f} (quartiles {np.quantile(gains, 0.25):.2f}-{np.quantile(gains, 0.75):.2f})")
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps({
            "share": share, "bins": dict(zip(names, (err_bins / total_err).tolist())),
            "bin_ratio": dict(zip(names, np.where(zero_bins > 0, err_bins / np.maximum(zero_bins, 1e-12), np.nan).tolist())),
            "oracle": {str(k): v / total_zero for k, v in oracle.items()}, "verdicts": verdicts,
            "median_gain": float(np.median(gains))}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
