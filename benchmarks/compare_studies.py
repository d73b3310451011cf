"""Two studies of the same people compared person by person: a second policy file against the first, and
against the first study's joystick and intent runs.

    python benchmarks/compare_studies.py --first docs/results/study/study.json \
        --second out/study_path_shape/study.json [--condition responsive] [--bootstrap 10000] [--out FILE.md]

`--second` is a `python -m rtcohand_drake.study --model FILE` run of the same populations, run seeds and
cap, with (at least) `--condition`. Each comparison is the study's own (`analysis.study_stats.compare`):
per-person paired ratios of completion time (a run that did not finish counts at the cap), the median
and the mean with bootstrap 95 % intervals, and the sign-flip test on their logarithms.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _load(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise SystemExit(f"error: {path}: {err}") from None


def main(argv=None) -> int:
    from rtcohand_drake.analysis.study_stats import compare

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--first", type=Path, required=True)
    p.add_argument("--second", type=Path, required=True)
    p.add_argument("--condition", default="responsive")
    p.add_argument("--bootstrap", type=int, default=10000)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    first, second = _load(args.first), _load(args.second)
    for key in ("populations", "run_seeds", "cap_s"):
        if first.get(key) != second.get(key):
            print(f"error: the studies differ in {key}: {first.get(key)} against {second.get(key)}", file=sys.stderr)
            return 2
    cap = float(first["cap_s"])
    c = args.condition
    label_second = f"{c}, second study ({Path(second.get('model') or 'the scenario file').name})"
    label_first = f"{c}, first study ({Path(first.get('model') or 'the scenario file').name})"
    merged: dict = {}
    for person, by_c in second["results"].items():
        if c not in by_c:
            continue
        runs = {label_second: by_c[c]}
        for name in (c, "joystick", "intent"):
            if name in first["results"].get(person, {}):
                runs[label_first if name == c else name] = first["results"][person][name]
        merged[person] = runs
    if not merged:
        print(f"error: {args.second} has no {c} runs", file=sys.stderr)
        return 2
    lines = [f"{len(merged)} people, run seeds {second['run_seeds']}, cap {cap:g} s", "",
             "| condition | against | people | median ratio (95 % CI) | mean ratio (95 % CI) | p (sign flip) | "
             "not done / runs | failed people |", "|---|---|---|---|---|---|---|---|"]
    for baseline in (label_first, "joystick", "intent"):
        r = compare(merged, label_second, baseline, cap, n_boot=args.bootstrap)
        if not r.ratios:
            continue
        lines.append(f"| {label_second} | {baseline} | {len(r.ratios)} | {r.median:.3f} ({r.median_ci[0]:.3f}-"
                     f"{r.median_ci[1]:.3f}) | {r.mean:.3f} ({r.mean_ci[0]:.3f}-{r.mean_ci[1]:.3f}) | {r.p_value:.3g} | "
                     f"{r.not_done[label_second]}/{r.runs[label_second]} against {r.not_done[baseline]}/"
                     f"{r.runs[baseline]} | {len(r.failed_people)} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
