"""Merge `evaluate` results.json files (the same data, episode seed and episodes) into one MSE table.

    python benchmarks/merge_results.py A/results.json B/results.json [...]

Each cell: MSE mean ± std over seeds, and its share of commanding zero twist.
The zero-twist and ridge rows come from the first file; the files must agree
on the data, the episode seed and the episodes per setting.
"""

import json
import pathlib
import sys

from rtcohand_drake.data.sampling import ALL_SETTINGS


def merged_table(results: list[dict]) -> str:
    first = results[0]
    for other in results[1:]:
        for key in ("data", "seed", "episodes"):
            if other[key] != first[key]:
                raise SystemExit(f"merge_results: the files differ in {key!r}: {first[key]} against {other[key]}")
    zero = first["reference"]["zero_twist_mse"]
    ridge = first["reference"]["ridge_mse"]
    settings = [s for s in ALL_SETTINGS if s in zero]
    lines = ["| model | seeds | " + " | ".join(settings) + " |", "|---|---|" + "---|" * len(settings)]
    for result in results:
        for name, model in result["models"].items():
            cells = []
            for s in settings:
                r = model["settings"].get(s)
                cells.append("-" if r is None else f"{r['mse']:.4f} ± {r['mse_std']:.4f} ({r['mse'] / zero[s]:.2f}x)")
            lines.append(f"| {name} | {model['seeds']} | " + " | ".join(cells) + " |")
    lines.append("| ridge fitted to the context (reference) | - | " + " | ".join(
        f"{ridge[s]:.4f} ({ridge[s] / zero[s]:.2f}x)" for s in settings) + " |")
    lines.append("| zero twist | - | " + " | ".join(f"{zero[s]:.4f}" for s in settings) + " |")
    lines += ["", "Episodes per setting: " + ", ".join(f"{s} {first['episodes'][s]}" for s in settings)]
    return "\n".join(lines)


if __name__ == "__main__":
    print(merged_table([json.loads(pathlib.Path(p).read_text()) for p in sys.argv[1:]]))
