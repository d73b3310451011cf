"""What recorded hands do that simulated ones do not: motion statistics of two gesture dataset files.

    python benchmarks/gesture_statistics.py --files REAL.h5 SIMULATED.h5 [--names real simulated]
        [--out DIR]

For every labelled clip, over the frames where its label is above 30 % of
its largest (the gesture),
from the raw keypoints at the file's own frame rate (no resampling):

- duration: seconds the label is above that;
- return: how far the hand comes back, 1 - |net displacement| / largest
  excursion of the palm centre (mean of the wrist and the four finger
  bases) from where the gesture started; 0 is a one-way motion, 1 a stroke
  that ends where it began;
- speed: the palm centre's peak and median speed over the gesture (m/s), from
  a 5-frame moving average of its position (jitter removed);
- fingers/palm: the fingertips' median speed relative to the palm centre,
  divided by the palm centre's median speed (how much the fingers move
  against the hand);
- jitter: the median, over clips, of the 99th percentile of the single-frame
  speed minus the smoothed speed (m/s), and the share of clips with a
  single-frame speed above 2 m/s;
- steadiness: the palm centre's distance from the median of the 5 frames
  around it (mm), its median and 99th percentile over the gesture's frames
  (how still the tracker holds a hand frame to frame, and how far it glitches).

Each statistic is the median over clips (and its 25-75 % range), except
has_fast_frame, the share of clips. Writes
DIR/gesture_statistics.json and prints a Markdown table. The recorded files
are read from the path given and never written into the repository.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

PALM = [0, 5, 9, 13, 17]
TIPS = [4, 8, 12, 16, 20]
SMOOTH_FRAMES = 5
# The gesture: the frames whose label exceeds this share of the clip's largest (a handler's labels are
# never exactly zero: they carry tracking noise and a lag's tail). The reading check's threshold.
ACTIVE_SHARE = 0.3
FAST_M_S = 2.0
SHARES = ("has_fast_frame",)  # reported as a share of clips (the mean), not a median


def smooth(p: np.ndarray, n: int = SMOOTH_FRAMES) -> np.ndarray:
    kernel = np.ones(n) / n
    padded = np.concatenate([np.repeat(p[:1], n // 2, 0), p, np.repeat(p[-1:], n // 2, 0)])
    return np.stack([np.convolve(padded[:, d], kernel, mode="valid") for d in range(p.shape[1])], 1)


def median_of_frames(p: np.ndarray, n: int = SMOOTH_FRAMES) -> np.ndarray:
    """Each frame's median over the n frames centred on it (the ends repeated)."""
    padded = np.concatenate([np.repeat(p[:1], n // 2, 0), p, np.repeat(p[-1:], n // 2, 0)])
    return np.median(np.stack([padded[i:i + len(p)] for i in range(n)]), axis=0)


def clip_statistics(keypoints: np.ndarray, labels: np.ndarray, fps: float) -> dict | None:
    size = np.abs(np.asarray(labels, np.float64)).max(1)
    on = np.flatnonzero(size > ACTIVE_SHARE * size.max())
    if on.size < SMOOTH_FRAMES + 2:
        return None
    kp = np.asarray(keypoints[on[0]:on[-1] + 1], np.float64)
    if not np.isfinite(kp).all():
        kp = kp[np.isfinite(kp).all(axis=(1, 2))]
        if len(kp) < SMOOTH_FRAMES + 2:
            return None
    palm = kp[:, PALM].mean(1)
    palm_s = smooth(palm)
    raw_speed = np.linalg.norm(np.diff(palm, axis=0), axis=1) * fps
    speed = np.linalg.norm(np.diff(palm_s, axis=0), axis=1) * fps
    excursion = np.linalg.norm(palm_s - palm_s[0], axis=1)
    largest = excursion.max()
    tips = smooth(kp[:, TIPS].reshape(len(kp), -1) - np.repeat(palm, 5, 1).reshape(len(kp), -1)).reshape(len(kp), 5, 3)
    steadiness = np.linalg.norm(palm - median_of_frames(palm), axis=1)
    tip_speed = np.median(np.linalg.norm(np.diff(tips, axis=0), axis=2).mean(1)) * fps
    return {
        "duration_s": on.size / fps,
        "return": float(1.0 - excursion[-1] / largest) if largest > 1e-6 else 0.0,
        "peak_speed_m_s": float(speed.max()),
        "median_speed_m_s": float(np.median(speed)),
        "fingers_over_palm": float(tip_speed / max(np.median(speed), 1e-6)),
        "jitter_p99_m_s": float(np.percentile(np.abs(raw_speed - speed), 99)),
        "has_fast_frame": float(np.any(raw_speed > FAST_M_S)),
        "steady_p50_mm": float(np.median(steadiness) * 1000),
        "steady_p99_mm": float(np.percentile(steadiness, 99) * 1000),
    }


def file_statistics(path: Path) -> dict:
    from rtcohand_drake.data.dataset import read_dataset

    rows = [s for c in read_dataset(path) if c.object_velocity is not None
            for s in [clip_statistics(c.keypoints, c.object_velocity, c.fps)] if s is not None]
    if not rows:
        raise SystemExit(f"{path}: no labelled clip long enough to measure")
    out = {"clips": len(rows)}
    for key in rows[0]:
        v = np.array([r[key] for r in rows])
        out[key] = {"mean": float(np.mean(v)), "median": float(np.median(v)), "p25": float(np.percentile(v, 25)),
                    "p75": float(np.percentile(v, 75))}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--files", nargs="+", required=True, type=Path)
    p.add_argument("--names", nargs="+", default=None)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    names = args.names or [f.stem for f in args.files]
    if len(names) != len(args.files):
        raise SystemExit("--names: one name per file")
    stats = {n: file_statistics(f) for n, f in zip(names, args.files)}
    keys = [k for k in next(iter(stats.values())) if k != "clips"]
    print("| statistic (median over clips, 25-75 %) | " + " | ".join(f"{n} ({stats[n]['clips']} clips)" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    for k in keys:
        print(f"| {k} | " + " | ".join(
            f"{stats[n][k]['mean']:.3g}" if k in SHARES else
            f"{stats[n][k]['median']:.3g} ({stats[n][k]['p25']:.3g}-{stats[n][k]['p75']:.3g})" for n in names) + " |")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "gesture_statistics.json").write_text(json.dumps(
            {"files": {n: str(f) for n, f in zip(names, args.files)}, "statistics": stats}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
