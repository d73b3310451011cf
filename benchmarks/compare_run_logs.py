"""Compare two run logs dataset by dataset: the check that a refactor changed no behaviour.

    python benchmarks/compare_run_logs.py BEFORE.h5 AFTER.h5 [--atol 0]

Prints each dataset and attribute that differs (the largest difference for
arrays) and exits 1 if any does. Attributes that name the machine's timing or
paths (none are written today) would be listed too, so a clean pass means
the two runs are the same.
"""

from __future__ import annotations

import argparse
import sys

import h5py
import numpy as np


def _items(f: h5py.File) -> dict:
    out = {}
    f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


def compare(a_path: str, b_path: str, atol: float = 0.0) -> list[str]:
    problems = []
    with h5py.File(a_path, "r") as a, h5py.File(b_path, "r") as b:
        da, db = _items(a), _items(b)
        for name in sorted(set(da) | set(db)):
            if name not in da or name not in db:
                problems.append(f"{name}: only in {'after' if name in db else 'before'}")
                continue
            x, y = da[name], db[name]
            if x.dtype.names or x.dtype.kind in "OSU":
                if x.shape != y.shape or not all(xi == yi for xi, yi in zip(x.tolist(), y.tolist())):
                    problems.append(f"{name}: differs ({len(x)} vs {len(y)} rows)")
            elif x.shape != y.shape:
                problems.append(f"{name}: shape {x.shape} vs {y.shape}")
            else:
                both_nan = np.isnan(x) & np.isnan(y) if x.dtype.kind == "f" else np.zeros(x.shape, bool)
                diff = np.where(both_nan, 0.0, np.abs(x.astype(float) - y.astype(float)))
                if diff.size and float(np.max(diff)) > atol:
                    problems.append(f"{name}: max |difference| {float(np.max(diff)):.3g}")
        for key in sorted(set(a.attrs) | set(b.attrs)):
            va, vb = a.attrs.get(key), b.attrs.get(key)
            same = (va == vb) if not isinstance(va, np.ndarray) else np.array_equal(va, vb)
            if isinstance(va, float) and isinstance(vb, float) and np.isnan(va) and np.isnan(vb):
                same = True
            if not np.all(same):
                problems.append(f"attribute {key}: {va!r} vs {vb!r}")
    return problems


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--atol", type=float, default=0.0, help="largest array difference accepted (default 0: identical)")
    args = p.parse_args(argv)
    problems = compare(args.before, args.after, args.atol)
    for line in problems:
        print(line)
    print("identical" if not problems else f"{len(problems)} differences")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
