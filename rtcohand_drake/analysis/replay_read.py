"""How well the policy read a replayed stream: its output against the labels of the clips played.

    python -m rtcohand_drake.run --gesture-source replay --gesture-file PEOPLE.h5 --clip PERSON --split test \
        --no-meshcat --log PERSON.h5                      # prints the figures below at the end of the run
    python -m rtcohand_drake.analysis.replay_read LOG.h5 [LOG.h5 ...] [--json OUT.json]   # pooled over runs

A replay of labelled clips logs each played frame's label (`/gesture/intended`, the replay source's
`intended_twist`) beside the policy box's output (`/policy/mean`: after the rest release, before the
command filter). The box's output logged one policy period after a frame is its read of that frame
(the log samples each period, and a sample shows the update made one period before), so each
label is paired with the output one period later. The figures:

- `share`: the squared error of the output against the labels, as a share of that of commanding
  zero twist (1: no better than zero);
- `rest_share`: of the rest steps (no label, from `REST_AFTER_S` after a label ends until the next
  starts), the share in which the output exceeds a fifth of a full command on any axis (`FULL`:
  0.12 m/s or 0.6 rad/s, the recorded labels' size): the command going on after the gesture stops;
- `wrong_way_share`: of the steps with a gesture under way (a label of at least a fifth of a full
  command on its largest axis), the share in which the output along that axis is below minus a
  fifth of a full command: the part sent against the gesture.

Over several runs, each figure pools the steps of all of them (`ReplayRead.pooled`).
`benchmarks/back_to_back_read.py` computes the same figures offline, from the dataset file.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import sys
from typing import Iterable, Sequence

import numpy as np

from rtcohand_drake.analysis.gesture_following import FULL_COMMAND as FULL

SHARE = 0.2  # a fifth of a full command
REST_AFTER_S = 0.5  # rest counted from this long after a gesture's label ends


def rest_steps(labels: np.ndarray, rate_hz: float) -> np.ndarray:
    """(T,) bool: steps with no label, from REST_AFTER_S after a label ends until the next starts."""
    on = np.abs(labels).max(1) > 0
    rest = np.zeros(len(labels), bool)
    last_on = -np.inf
    wait = int(round(REST_AFTER_S * rate_hz))
    for t, active in enumerate(on):
        if active:
            last_on = t
        elif t - last_on > wait and last_on > -np.inf:
            rest[t] = True
    return rest


@dc.dataclass
class ReplayRead:
    """The figures' sums over one stream, or several pooled (module docstring)."""

    error: float = 0.0  # sum of the squared error of the output against the labels
    zero: float = 0.0  # the same for zero twist: the labels' squared size
    rest_steps: int = 0
    rest_moving: int = 0  # rest steps over a fifth of a full command
    gesture_steps: int = 0
    against: int = 0  # gesture steps against the gesture

    @property
    def share(self) -> float:
        return self.error / self.zero if self.zero > 0 else float("nan")

    @property
    def rest_share(self) -> float:
        return self.rest_moving / self.rest_steps if self.rest_steps else float("nan")

    @property
    def wrong_way_share(self) -> float:
        return self.against / self.gesture_steps if self.gesture_steps else float("nan")

    @staticmethod
    def pooled(reads: Iterable["ReplayRead"]) -> "ReplayRead":
        total = ReplayRead()
        for r in reads:
            for f in dc.fields(ReplayRead):
                setattr(total, f.name, getattr(total, f.name) + getattr(r, f.name))
        return total

    def line(self) -> str:
        rest = (f"at rest over a fifth of a full command in {100 * self.rest_share:.1f} % of {self.rest_steps} steps"
                if self.rest_steps else "no rest steps")
        against = (f"against the gesture in {100 * self.wrong_way_share:.1f} % of {self.gesture_steps} steps"
                   if self.gesture_steps else "no gesture steps")
        return f"{self.share:.3f} of zero twist's squared error; {rest}; {against}"

    def as_dict(self) -> dict:
        shares = {"share": self.share, "rest_share": self.rest_share, "wrong_way_share": self.wrong_way_share}
        return {**dc.asdict(self), **{k: (v if np.isfinite(v) else None) for k, v in shares.items()}}


def read_figures(out: np.ndarray, labels: np.ndarray, rate_hz: float) -> ReplayRead:
    """The figures of outputs (T, 6) against labels (T, 6), step t's output being the read of step t."""
    out, labels = np.nan_to_num(np.asarray(out, np.float64)), np.nan_to_num(np.asarray(labels, np.float64))
    if out.shape != labels.shape:
        raise ValueError(f"read_figures: outputs {out.shape} and labels {labels.shape} differ")
    rest = rest_steps(labels, rate_hz)
    moving = (np.abs(out) / FULL).max(1) > SHARE
    scaled = labels / FULL
    axis = np.abs(scaled).argmax(1)
    rows = np.arange(len(labels))
    under_way = np.abs(scaled[rows, axis]) >= SHARE
    along = np.sign(scaled[rows, axis]) * out[rows, axis] / FULL[axis]
    return ReplayRead(error=float(((out - labels) ** 2).sum()), zero=float((labels ** 2).sum()),
                      rest_steps=int(rest.sum()), rest_moving=int((rest & moving).sum()),
                      gesture_steps=int(under_way.sum()), against=int((under_way & (along < -SHARE)).sum()))


def paired(log) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(outputs (T, 6), labels (T, 6), rate in Hz) of a run log (`run_log.RunLog`) whose source logged
    the labels it played, each label beside the box's read of its frame; None for a log without them
    (another source, or clips without labels)."""
    times, labels = np.asarray(log.gesture_time, float), np.asarray(log.gesture_intended, float)
    policy_times = np.asarray(log.policy_time, float)
    if len(times) < 2 or len(labels) != len(times) or len(policy_times) < 2:
        return None
    period = float(np.median(np.diff(policy_times)))
    # The output that read the frame played at t is the one logged at t + period.
    k = np.searchsorted(policy_times, times + period - 1e-6 * period)
    found = k < len(policy_times)
    found[found] = np.abs(policy_times[k[found]] - (times[found] + period)) < 1e-3 * period
    if not found.any():
        return None
    return np.asarray(log.policy_mean, float)[k[found]], labels[found], 1.0 / period


def log_read(log) -> ReplayRead | None:
    """The figures of a run log (`paired`); None for a log without the labels played."""
    pairs = paired(log)
    return None if pairs is None else read_figures(*pairs)


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.analysis.replay_read",
                                description=__doc__.splitlines()[0])
    p.add_argument("logs", nargs="+", help="run logs of replays of labelled clips (run --log)")
    p.add_argument("--json", default=None, help="write each log's figures and the pooled ones to this file")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    from rtcohand_drake.errors import InputError
    from rtcohand_drake.run_log import read_run_log

    reads = []
    for path in args.logs:
        r = log_read(read_run_log(path))
        if r is None:
            raise InputError(f"{path}: the run log holds no labels of replayed clips (a replay of labelled clips "
                             "logs them)")
        reads.append(r)
        print(f"{path}: {r.line()}")
    total = ReplayRead.pooled(reads)
    if len(reads) > 1:
        print(f"pooled over {len(reads)} runs: {total.line()}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"runs": [{"log": str(p), **r.as_dict()} for p, r in zip(args.logs, reads)],
                       "pooled": total.as_dict()}, f, indent=1)
    return 0


def entry_point() -> None:
    from rtcohand_drake.errors import run_cli

    sys.exit(run_cli(main, prog="rtcohand_drake.analysis.replay_read"))


if __name__ == "__main__":
    entry_point()
