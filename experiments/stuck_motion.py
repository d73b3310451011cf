"""Where does a recorded person's unfinished run get stuck? The motion they keep gesturing at the end, and how
much of it the read gives.

    python experiments/stuck_motion.py --logs DIR/logs/*_responsive_*.h5 [--last 300]

For each run log of `study --recorded-people` that did not complete: over its last `--last` seconds, the
policy steps in which the person gestures (the label of the frame played over a fifth of a full command on
some axis: 0.12 m/s, 0.6 rad/s), the motion of each such step (the label's largest axis as a share of a full
command, with its sign), the three motions gestured most, and per axis the policy's gain over those steps:
the least-squares factor of its output (`policy/mean`) on the label, sum(mean y) / sum(y^2), over the steps
where that axis is gestured (1: the label's size; at least 20 steps). The findings: docs/real_people.md,
"Given more time".
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
FULL = np.array([0.12] * 3 + [0.6] * 3)  # a full command: the importer's label magnitudes
SHARE = 0.2  # a gesture under way: a fifth of a full command


def stuck(path: pathlib.Path, last_s: float) -> dict | None:
    """The figures of one run log (module docstring); None for a completed run."""
    import h5py

    with h5py.File(path, "r") as f:
        if bool(f.attrs.get("completed", False)):
            return None
        t = f["gesture/time"][:]
        label = f["gesture/intended"][:]
        mean = f["policy/mean"][:]
        faces = int(f.attrs.get("faces_inspected", 0))
    n = min(len(t), len(label), len(mean))
    keep = t[:n] > t[n - 1] - last_s if n else np.zeros(0, bool)
    label, mean = label[:n][keep], mean[:n][keep]
    size = np.abs(label) / FULL
    gesturing = (size > SHARE).any(1)
    counts: dict[str, int] = {}
    for i in np.flatnonzero(gesturing):
        d = int(np.argmax(size[i]))
        name = AXES[d] + ("+" if label[i, d] > 0 else "-")
        counts[name] = counts.get(name, 0) + 1
    gains = {}
    for d, axis in enumerate(AXES):
        on = size[:, d] > SHARE
        if on.sum() >= 20:
            gains[axis] = float((mean[on, d] * label[on, d]).sum() / (label[on, d] ** 2).sum())
    return {"faces": faces, "gesturing_steps": int(gesturing.sum()),
            "motions": sorted(counts.items(), key=lambda kv: -kv[1])[:3], "gains": gains}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--logs", nargs="+", required=True, type=pathlib.Path, help="study run logs (.h5)")
    p.add_argument("--last", type=float, default=300.0, help="seconds at the end of each run to read")
    args = p.parse_args(argv)
    for path in sorted(args.logs):
        r = stuck(path, args.last)
        if r is None:
            continue
        motions = ", ".join(f"{m} {c}" for m, c in r["motions"]) or "none"
        gains = ", ".join(f"{a} {g:+.2f}" for a, g in r["gains"].items()) or "-"
        print(f"{path.name}: {r['faces']}/6 faces; last {args.last:.0f} s: {r['gesturing_steps']} gesturing steps "
              f"({motions}); the read's gain per axis: {gains}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
