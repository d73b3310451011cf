"""Plots one recorded person's run beside the intent reference: the part's path and the hand's.

    python docs/plot_recorded_paths.py --logs DIR --person s10 --out PATH.png [--part-only]

DIR is a recorded study's logs folder (`python -m rtcohand_drake.study
--recorded-people ... --out OUT`, logs in OUT/logs). For the person's
`responsive` and `intent` runs (run seed 0) it draws, in the user frame U
as the inspector faces the cell (X right, Z up), the workpiece centre's
path and, unless `--part-only`, the path of the hand's palm centre (the
recorded hand as played: derived from the recording, so keep such a plot
out of the repository; the part's path alone may be committed).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def part_path_U(log, scenario) -> np.ndarray:
    """(K, 3) the workpiece centre in U."""
    X_WU = scenario.cell.user_frame.to_rigid_transform()
    return (log.robot_workpiece_pose[:, :3] - X_WU.translation()) @ X_WU.rotation().matrix()


def palm_path_U(log) -> np.ndarray:
    """(G, 3) the palm centre (wrist and finger bases) of the logged skeletons, U."""
    kp = log.gesture_keypoints.reshape(-1, 21, 3)
    return kp[:, [0, 5, 9, 13, 17]].mean(axis=1)


def main() -> int:
    from matplotlib.figure import Figure

    from rtcohand_drake.run_log import read_run_log
    from rtcohand_drake.scenario import load_scenario

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--logs", type=Path, required=True)
    p.add_argument("--person", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--part-only", action="store_true", help="the part's path alone (no recorded hand)")
    args = p.parse_args()
    scenario = load_scenario("inspection")
    conditions = ("responsive", "intent")
    rows = 1 if args.part_only else 2
    fig = Figure(figsize=(10, 4.2 * rows))
    axes = np.atleast_2d(fig.subplots(rows, 2))
    for j, condition in enumerate(conditions):
        path = args.logs / f"{args.person}_{condition}_s{args.seed}.h5"
        log = read_run_log(path)
        done = f"{log.completion_time:.1f} s" if log.completed else "not done"
        part = part_path_U(log, scenario)
        ax = axes[0, j]
        points = ax.scatter(part[:, 0], part[:, 2], c=log.robot_time, s=2, cmap="viridis")
        ax.set_title(f"{args.person}, {condition}: the part ({log.faces_inspected}/6 faces, {done})")
        ax.set_xlabel("X of U (m)")
        ax.set_ylabel("Z of U (m)")
        ax.set_aspect("equal", adjustable="datalim")
        fig.colorbar(points, ax=ax, label="time (s)")
        if not args.part_only:
            palm = palm_path_U(log)
            ok = np.all(np.isfinite(palm), axis=1)
            ax = axes[1, j]
            points = ax.scatter(palm[ok, 0], palm[ok, 2], c=log.gesture_time[ok], s=2, cmap="viridis")
            gesture = np.any(log.gesture_intended != 0, axis=1) & ok
            ax.plot(palm[gesture, 0], palm[gesture, 2], ".", ms=1, color="C3", label="during a gesture")
            ax.set_title(f"{args.person}, {condition}: the hand's palm centre")
            ax.set_xlabel("X of U (m)")
            ax.set_ylabel("Z of U (m)")
            ax.set_aspect("equal", adjustable="datalim")
            ax.legend(loc="best", fontsize=8)
            fig.colorbar(points, ax=ax, label="time (s)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
