"""Can any linear read of the hand features tell a finger sweep's direction? Development people only.

    python experiments/sweep_decodability.py --population-seeds 0 3 4 5 6 7 8 [--model M.pt] [--out DIR]

Some simulated people give a motion by sweeping their fingers (flex, spread
or a thumb flick), the direction carried by which stroke is fast. For every
out-sample person of the given populations who does, and for each such
motion, this reports the reading gain (the held-out read over the label,
median over the motion's clips, the definition of `context_reading`) of:

- the policy file (`--model`; default the shipped one), the person's other
  clips as context in six folds, as `report_populations.py` reads them;
- ridge regressions fitted to the person's own clips in the same folds
  (`rtcohand_drake.learning.ridge_reference`, 10 frames, lambda 100), on
  three per-frame feature sets: the 36 part velocities x (the reference);
  x and x |x| (a stroke's asymmetry, the sign of a sweep); and those plus the
  five fingers' velocities relative to the palm's, u and u |u| (the hand's
  articulation alone, without its motion); and, from the keypoints rather
  than the 36 features, the fingertips' velocities in the palm's frame,
  t and t |t| (15 + 15);
- each ridge twice: from the keypoints as recorded (camera jitter and lost
  frames) and from the generator's noise-free keypoints of the same clips
  (`ClipTruth.keypoints_clean`), which no camera gives: it says whether the
  direction is in the hand's motion at all, or lost in the camera's noise.

For comparison, each person's median ridge gain over their other motions is
given too. Choose nothing from this on populations of seed 100 or more.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OUT_SAMPLE = (10, 11, 12, 13, 14)
FEATURE_SETS = ("x", "x, x|x|", "x, x|x|, u, u|u|", "tips t, t|t|")
TIPS = [4, 8, 12, 16, 20]


def fingertip_velocities(keypoints: np.ndarray, fps: float, timestamps) -> np.ndarray:
    """(T, 15): the five fingertips' velocities in the palm's frame (m/s) at 10 Hz, from keypoints."""
    from rtcohand_drake.data.hand_features import (
        DEFAULT_MAX_GAP_S, frame_times, interpolate_keypoints, part_frames, policy_times)

    times = frame_times(keypoints.shape[0], fps, timestamps)
    tq = policy_times(times, 10.0)
    kq, _ = interpolate_keypoints(keypoints, times, tq, max(DEFAULT_MAX_GAP_S, 1.5 / fps))
    R, o = part_frames(kq)
    in_palm = np.einsum("tji,tkj->tki", R[:, 0], kq[:, TIPS] - o[:, :1])  # R^T (p - o)
    v = np.diff(in_palm.reshape(len(tq), -1), axis=0, prepend=in_palm[:1].reshape(1, -1)) * 10.0
    return np.nan_to_num(v, nan=0.0)


def frame_features(x: np.ndarray, kind: str) -> np.ndarray:
    """Per-frame inputs of one feature set from the 36 part velocities x (T, 36), or, for
    "tips t, t|t|", from the fingertip velocities (T, 15)."""
    if kind == "tips t, t|t|":
        return np.concatenate([x, x * np.abs(x)], 1)
    cols = [x]
    if kind != "x":
        cols.append(x * np.abs(x))
    if kind == "x, x|x|, u, u|u|":
        parts = x.reshape(len(x), 6, 6)
        u = (parts[:, 1:] - parts[:, :1]).reshape(len(x), 30)
        cols += [u, u * np.abs(u)]
    return np.concatenate(cols, 1)


def ridge_gains(clips, tips, kind: str) -> dict[str, float]:
    """Median reading gain per motion of the ridge on feature set `kind`, six folds (`tips`: each
    clip's fingertip velocities)."""
    from rtcohand_drake.analysis.context_reading import LabelledClip, held_out_readings, held_out_reference_means, motion_table

    wide = [LabelledClip(c.name, frame_features(t if kind == "tips t, t|t|" else c.features.astype(np.float64), kind),
                         c.labels, c.active_dims) for c, t in zip(clips, tips)]
    means = held_out_reference_means(wide, 6)
    return {m: g for m, _, g, _ in motion_table(held_out_readings(None, wide, means=means))}


def person_clips(raw, truths, clean: bool):
    """The person's clips at 10 Hz (features from the recorded or the noise-free keypoints), and
    each clip's fingertip velocities."""
    from rtcohand_drake.analysis.context_reading import LabelledClip
    from rtcohand_drake.data.dataset import to_policy_clip
    from rtcohand_drake.data.hand_features import hand_features

    out, tips = [], []
    for clip, truth in zip(raw, truths):
        pc = to_policy_clip(clip, 10.0)
        features = pc.features
        keypoints = truth.keypoints_clean if clean else clip.keypoints
        if clean:
            features, _ = hand_features(keypoints, clip.fps, 10.0, clip.timestamps)
        out.append(LabelledClip(pc.name, features, pc.labels, tuple(int(d) for d in clip.active_dims)))
        tips.append(fingertip_velocities(np.asarray(keypoints, np.float64), clip.fps, clip.timestamps)[: len(features)])
    return out, tips


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--population-seeds", type=int, nargs="+", required=True)
    p.add_argument("--model", default=str(REPO / "models" / "cchp_default.pt"))
    p.add_argument("--out", type=Path, default=REPO / "out" / "sweep")
    args = p.parse_args(argv)
    if any(s >= 100 for s in args.population_seeds):
        p.error("development populations only (seeds 0-99)")

    from rtcohand_drake.analysis.context_reading import held_out_means, held_out_readings, motion_table
    from rtcohand_drake.data.dataset import DIMENSIONS
    from rtcohand_drake.data.population import GeneratorConfig, simulate_user, user_groups
    from rtcohand_drake.learning.policy_file import load_policy

    module = load_policy(args.model)
    config = GeneratorConfig()
    groups = user_groups(15, config)
    rows, summary = [], []
    for seed in args.population_seeds:
        for i in OUT_SAMPLE:
            user, raw, truths = simulate_user(config, i, groups[i], seed)
            sweeps = {(d, s): g for (d, s), g in user.gestures.items() if g.kind == "sweep"}
            if not sweeps:
                continue
            recorded, tips_recorded = person_clips(raw, truths, clean=False)
            clean, tips_clean = person_clips(raw, truths, clean=True)
            policy = {m: g for m, _, g, _ in motion_table(held_out_readings(None, recorded, means=held_out_means(module, recorded, 6)))}
            ridge = {(kind, c): ridge_gains(clips, tips, kind) for kind in FEATURE_SETS
                     for c, clips, tips in (("recorded", recorded, tips_recorded), ("noise-free", clean, tips_clean))}
            sweep_names = {f"{DIMENSIONS[d]}{'+' if s > 0 else '-'}" for d, s in sweeps}
            others = [ridge[("x, x|x|", "recorded")][m] for m in policy if m not in sweep_names]
            for (d, s), g in sorted(sweeps.items()):
                name = f"{DIMENSIONS[d]}{'+' if s > 0 else '-'}"
                row = {"person": f"p{seed}/u{i}", "motion": name, "gesture": g.describe(),
                       "posture": "curled" if user.curled_posture else "extended", "policy": policy[name],
                       "ridge": {f"{kind} ({c})": v[name] for (kind, c), v in ridge.items()},
                       "ridge_other_motions_median": float(np.median(others))}
                rows.append(row)
                print(json.dumps(row), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "sweep_decodability.json").write_text(json.dumps({"model": Path(args.model).name,
                                                                   "population_seeds": args.population_seeds,
                                                                   "rows": rows}, indent=1))
    cols = [f"{kind} ({c})" for kind in FEATURE_SETS for c in ("recorded", "noise-free")]
    lines = ["| person | motion | gesture | posture | policy | " + " | ".join(f"ridge {c}" for c in cols)
             + " | ridge x, x|x| (recorded), the person's other motions |",
             "|" + "---|" * (6 + len(cols))]
    for r in rows:
        lines.append(f"| {r['person']} | {r['motion']} | {r['gesture']} | {r['posture']} | {r['policy']:+.2f} | "
                     + " | ".join(f"{r['ridge'][c]:+.2f}" for c in cols) + f" | {r['ridge_other_motions_median']:+.2f} |")
    table = "\n".join(lines)
    (args.out / "sweep_decodability.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
