"""Paired statistics of a study: per-person ratios of completion times, bootstrap intervals, a paired test.

The study's results are `{person: {condition: {run_seed: summary or None}}}`,
where a summary is `analysis.study.summarise`'s dict and None marks a run that
failed with an error (after its retry). Between a condition and a baseline:

- A person's time in a condition is the mean over their run seeds of the
  completion time. A run that did not finish (the cap reached, or a safety
  contact) counts as the cap time, `cap_s`: a person who does not finish is
  never dropped from a ratio, and is counted beside it.
- The person's paired ratio is their time in the condition over their time
  in the baseline.
- A person with a failed run (an error, not a slow finish) in either
  condition has no time there. They are left out of that comparison and
  counted as such.
- The median and the mean of the ratios each get a percentile bootstrap
  95 % interval: people resampled with replacement, `n_boot` times, from a
  fixed seed.
- The paired test is a sign-flip (randomisation) test of the mean log-ratio
  against 0: under "the condition makes no difference", each person's
  log-ratio is as likely negative as positive. It is exact (every sign
  pattern) up to 16 people, and uses `n_flip` random patterns above that.
  The p-value is two-sided.
"""

from __future__ import annotations

import dataclasses as dc
import itertools
from typing import Mapping

import numpy as np


@dc.dataclass
class Comparison:
    condition: str
    baseline: str
    ratios: dict[str, float]  # person -> paired ratio
    median: float
    median_ci: tuple[float, float]
    mean: float
    mean_ci: tuple[float, float]
    p_value: float
    not_done: dict[str, int]  # condition -> runs that did not finish (counted at the cap)
    failed_people: list[str]  # left out: a run failed with an error in either condition
    runs: dict[str, int]  # condition -> runs counted

    @property
    def n(self) -> int:
        return len(self.ratios)

    def line(self) -> str:
        """One Markdown line: the ratio with its intervals, the test, and what was counted at the cap."""
        if not self.ratios:
            return f"- **{self.condition} / {self.baseline}**: no person with runs in both"
        lo, hi = self.median_ci
        mlo, mhi = self.mean_ci
        text = (f"- **{self.condition} / {self.baseline}**: median {self.median:.2f} (95 % CI {lo:.2f}-{hi:.2f}), "
                f"mean {self.mean:.2f} (95 % CI {mlo:.2f}-{mhi:.2f}), {self.n} people; paired sign-flip test "
                f"p = {self.p_value:.3g}; runs not finished, counted at the cap: "
                + ", ".join(f"{c} {self.not_done[c]}/{self.runs[c]}" for c in (self.condition, self.baseline)))
        if self.failed_people:
            text += f"; left out for a failed run: {len(self.failed_people)} ({', '.join(self.failed_people)})"
        return text


def person_time(runs: Mapping[int, dict | None], cap_s: float) -> float | None:
    """Mean completion time over run seeds, a run not finished counted at `cap_s`; None if a run failed."""
    if not runs or any(r is None for r in runs.values()):
        return None
    return float(np.mean([r["completion_s"] if r["completed"] else cap_s for r in runs.values()]))


def bootstrap_ci(values, statistic=np.median, n_boot: int = 10000, level: float = 0.95,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of `statistic` over `values` (resampled with replacement)."""
    x = np.asarray(values, float)
    if len(x) == 0:
        return (float("nan"), float("nan"))
    rng = np.random.default_rng(seed)
    samples = x[rng.integers(0, len(x), size=(n_boot, len(x)))]
    stats = statistic(samples, axis=1)
    a = (1.0 - level) / 2.0
    return float(np.quantile(stats, a)), float(np.quantile(stats, 1.0 - a))


def sign_flip_p(differences, n_flip: int = 20000, seed: int = 0, exact_up_to: int = 16) -> float:
    """Two-sided p-value of the paired sign-flip test of mean(differences) = 0."""
    d = np.asarray(differences, float)
    if len(d) == 0:
        return float("nan")
    observed = abs(d.mean())
    if len(d) <= exact_up_to:
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=len(d))))
    else:
        rng = np.random.default_rng(seed)
        signs = rng.choice((1.0, -1.0), size=(n_flip, len(d)))
    null = np.abs((signs * d).mean(axis=1))
    # The observed pattern is one of the patterns (exact), or counted in (random: never p = 0).
    if len(d) <= exact_up_to:
        return float(np.mean(null >= observed - 1e-12))
    return float((np.sum(null >= observed - 1e-12) + 1) / (len(null) + 1))


def compare(results: Mapping[str, Mapping[str, Mapping[int, dict | None]]], condition: str, baseline: str,
            cap_s: float, n_boot: int = 10000, seed: int = 0) -> Comparison:
    """The paired comparison of `condition` against `baseline` (module docstring)."""
    ratios, failed = {}, []
    not_done = {condition: 0, baseline: 0}
    runs = {condition: 0, baseline: 0}
    for person, by_condition in results.items():
        if condition not in by_condition or baseline not in by_condition:
            continue
        a, b = person_time(by_condition[condition], cap_s), person_time(by_condition[baseline], cap_s)
        if a is None or b is None:
            failed.append(person)
            continue
        for c in (condition, baseline):
            runs[c] += len(by_condition[c])
            not_done[c] += sum(not r["completed"] for r in by_condition[c].values())
        ratios[person] = a / b
    r = np.array(list(ratios.values()))
    return Comparison(
        condition, baseline, ratios,
        median=float(np.median(r)) if len(r) else float("nan"),
        median_ci=bootstrap_ci(r, np.median, n_boot, seed=seed),
        mean=float(np.mean(r)) if len(r) else float("nan"),
        mean_ci=bootstrap_ci(r, np.mean, n_boot, seed=seed),
        p_value=sign_flip_p(np.log(r), seed=seed),
        not_done=not_done, failed_people=failed, runs=runs)
