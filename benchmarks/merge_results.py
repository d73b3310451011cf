"""Merge `evaluate` results.json files (the same data, episode seed and episodes) into one MSE table.

    python benchmarks/merge_results.py A/results.json B/results.json [...]

Each cell: MSE mean ± std over seeds, and its share of commanding zero twist.
"""
import json
import sys


def main(paths):
    docs = [json.load(open(p)) for p in paths]
    settings = ["D+U+", "D+U-", "D-U+", "D-U-", "Unseen", "Noisy", "Own"]
    ref = docs[0]["reference"]
    for d in docs[1:]:
        for s in settings:
            a, b = d["reference"]["zero_twist_mse"].get(s), ref["zero_twist_mse"].get(s)
            assert a is None or b is None or abs(a - b) < 1e-12, (s, a, b)
    zero = ref["zero_twist_mse"]
    rows = []
    for d in docs:
        for name, m in d["models"].items():
            cells = []
            for s in settings:
                r = m["settings"].get(s)
                cells.append("-" if r is None else f"{r['mse']:.4f} ± {r['mse_std']:.4f} ({r['mse'] / zero[s]:.2f}x)")
            rows.append(f"| {name} | {m['seeds']} | " + " | ".join(cells) + " |")
    rows.append("| ridge fitted to the context (reference) | - | " + " | ".join(
        f"{ref['ridge_mse'][s]:.4f} ({ref['ridge_mse'][s] / zero[s]:.2f}x)" for s in settings) + " |")
    rows.append("| zero twist | - | " + " | ".join(f"{zero[s]:.4f}" for s in settings) + " |")
    print("| model | seeds | " + " | ".join(settings) + " |")
    print("|---|---|" + "---|" * len(settings))
    print("\n".join(rows))
    print()
    print("Episodes per setting: " + ", ".join(f"{s} {docs[0]['episodes'][s]}" for s in settings))


if __name__ == "__main__":
    main(sys.argv[1:])
