"""Merge `evaluate` results.json files (the same data, episode seed and episodes) into one MSE table.

    python benchmarks/merge_results.py A/results.json B/results.json [...]

Each cell: MSE mean ± std over seeds, and its share of commanding zero twist.
The zero-twist and ridge rows come from the first file; the files must agree
on the episode seed and the episodes per setting, and on the data: the same
path, or, for a dataset file at another path (regenerated with the same
command), the same zero-twist and ridge MSE in every setting they share,
which only the same episodes give.
"""

import json
import pathlib
import sys

from rtcohand_drake.data.sampling import ALL_SETTINGS


def _same_references(a: dict, b: dict) -> bool:
    """Whether two results have the same zero-twist and ridge MSE in every setting both hold."""
    for key in ("zero_twist_mse", "ridge_mse"):
        ra, rb = a["reference"].get(key, {}), b["reference"].get(key, {})
        shared = set(ra) & set(rb)
        if key == "ridge_mse" and not ra and not rb:
            continue  # results written before the ridge reference
        if not shared or any(abs(ra[s] - rb[s]) > 1e-12 * max(1.0, abs(ra[s])) for s in shared):
            return False
    return True


def merged_table(results: list[dict]) -> str:
    first = results[0]
    for other in results[1:]:
        for key in ("seed", "episodes"):
            if other[key] != first[key]:
                raise SystemExit(f"merge_results: the files differ in {key!r}: {first[key]} against {other[key]}")
        if other["data"] != first["data"] and not _same_references(first, other):
            raise SystemExit(f"merge_results: the files differ in 'data': {first['data']} against {other['data']}, "
                             "and their zero-twist or ridge MSE differ")
    zero = first["reference"]["zero_twist_mse"]
    ridge = first["reference"].get("ridge_mse")  # absent from results written before the ridge reference
    settings = [s for s in ALL_SETTINGS if s in zero]
    lines = ["| model | seeds | " + " | ".join(settings) + " |", "|---|---|" + "---|" * len(settings)]
    for result in results:
        for name, model in result["models"].items():
            cells = []
            for s in settings:
                r = model["settings"].get(s)
                cells.append("-" if r is None else f"{r['mse']:.4f} ± {r['mse_std']:.4f} ({r['mse'] / zero[s]:.2f}x)")
            lines.append(f"| {name} | {model['seeds']} | " + " | ".join(cells) + " |")
    if ridge:
        lines.append("| ridge fitted to the context (reference) | - | " + " | ".join(
            f"{ridge[s]:.4f} ({ridge[s] / zero[s]:.2f}x)" if s in ridge else "-" for s in settings) + " |")
    lines.append("| zero twist | - | " + " | ".join(f"{zero[s]:.4f}" for s in settings) + " |")
    lines += ["", "Episodes per setting: " + ", ".join(f"{s} {first['episodes'][s]}" for s in settings)]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if not argv or any(a.startswith("-") for a in argv):
        print("usage: python benchmarks/merge_results.py A/results.json B/results.json [...]", file=sys.stderr)
        return 2
    results = []
    for path in argv:
        try:
            results.append(json.loads(pathlib.Path(path).read_text()))
        except (OSError, ValueError) as err:
            print(f"merge_results: {path}: not a readable results.json ({type(err).__name__})", file=sys.stderr)
            return 2
    try:
        print(merged_table(results))
    except (KeyError, TypeError, AttributeError) as err:
        print(f"merge_results: not an evaluate results.json (no {err})", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
