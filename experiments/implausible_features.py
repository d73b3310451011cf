"""How often do real hands' features trip the safety supervisor's plausibility check, and on what?

    python experiments/implausible_features.py --videos DIR [--data PEOPLE.h5 ...] [--limit 25]

The supervisor stops the arm (its watchdog) on a policy step whose features show a hand part faster
than a hand can move (`safety.rules.plausible_features`). This counts, at the policy rate (10 Hz), the
steps whose largest linear velocity (m/s) or angular velocity (rad/s) of a hand part is over `--limit`:
for each video file of a folder, as the run's video source reads it (MediaPipe, the camera's default
settings); for each file of recorded people (the importer's), over all their clips. A part's angular
velocity is the rotation between two poses over their time apart, so it is at most pi / dt (31 rad/s at
10 Hz); a finger frame that flips half a turn between two frames reaches it. The findings:
docs/safety.md, "What each fault does" (a finger frame's half turn).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

VIDEO_SUFFIXES = (".gif", ".mp4", ".avi", ".mov", ".mkv", ".webm")


def video_features(path: Path, rate_hz: float) -> np.ndarray:
    """(N, 36) features of the policy steps with a hand seen in this step and the one before."""
    from rtcohand_drake.data.hand_features import HandFeatureStream
    from rtcohand_drake.vision.calibration import CameraCalibration
    from rtcohand_drake.vision.capture import HandPipeline, VideoFileTracker
    from rtcohand_drake.vision.config import Camera

    tracker = VideoFileTracker(path, HandPipeline(CameraCalibration(), Camera()))
    stream, rows = HandFeatureStream(), []
    try:
        for k in range(int(tracker.duration_s * rate_hz)):
            keypoints, t = tracker.latest(k / rate_hz)
            x, ok = stream.update(np.full((21, 3), np.nan) if keypoints is None else keypoints, t)
            if ok:
                rows.append(x)
    finally:
        tracker.close()
    return np.array(rows, np.float64).reshape(-1, 36)


def counts(x: np.ndarray, limit: float) -> str:
    parts = np.abs(x).reshape(len(x), 6, 6)
    linear, angular = parts[:, :, :3].max((1, 2)), parts[:, :, 3:].max((1, 2))
    over_l, over_a = int((linear > limit).sum()), int((angular > limit).sum())
    worst = f", largest {linear.max():.1f} m/s and {angular.max():.1f} rad/s" if len(x) else ""
    return (f"{len(x)} steps, {over_l + over_a - int(((linear > limit) & (angular > limit)).sum())} over {limit:g} "
            f"({over_l} linear, {over_a} angular){worst}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--videos", type=Path, default=None, help="a folder of video files")
    p.add_argument("--data", type=Path, nargs="*", default=[], help="files of recorded people")
    p.add_argument("--limit", type=float, default=25.0)
    p.add_argument("--rate-hz", type=float, default=10.0)
    args = p.parse_args(argv)
    if args.videos is not None:
        paths = sorted(q for q in args.videos.iterdir() if q.suffix.lower() in VIDEO_SUFFIXES)
        every = []
        for q in paths:
            x = video_features(q, args.rate_hz)
            every.append(x)
            print(f"{q.name}: {counts(x, args.limit)}", flush=True)
        print(f"all {len(paths)} videos: {counts(np.concatenate(every) if every else np.zeros((0, 36)), args.limit)}")
    for data in args.data:
        from rtcohand_drake.data.dataset import load_policy_clips

        x = np.concatenate([np.nan_to_num(np.asarray(c.features, np.float64))
                            for c in load_policy_clips(data, args.rate_hz, False)])
        print(f"{data.name}: {counts(x, args.limit)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
