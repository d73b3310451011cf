"""How often does a person's palm turn fast? The share of a context's moving steps with the palm over 2 rad/s.

    python experiments/fast_turn_share.py --data POP.h5 [--every 8]                 # a generated population
    python experiments/fast_turn_share.py --data MAP.h5 --people s02 s04 ...          # recorded people
    python experiments/fast_turn_share.py --videos DIR                                # video files of a real hand

The shipped policy file gives a person its kernel read of the hand's path and shape only where their
context's palm turns faster than `FAST_TURN_RAD_S` in at least `--min-fast-turns` of its moving steps
(`learning.path_shape_policy`). This prints that share, computed by the file's own `fast_turn_share`
(`--file`, default the shipped one), for: every `--every`-th Own episode's context of a generated
population (`data.sampling.evaluation_episodes`, seed 0), summarised; each recorded person's
`split = train` clips, as the run reads them; or each video file in DIR played as the run's video
source plays it (MediaPipe through `HandPipeline`, polled at 10 Hz; the default calibration), then all
of them pooled. Nothing derived from the data is written.

Findings: docs/policy.md, "One file for every hand".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

VIDEO_SUFFIXES = (".gif", ".mp4", ".avi", ".mov", ".mkv", ".webm")


def share(module, pieces) -> float:
    import torch

    from rtcohand_drake.data.sampling import pack_context

    x, y, m = (torch.from_numpy(a) for a in pack_context(pieces))
    return float(module.fast_turn_share(x, m))


def video_features(path: Path, rate_hz: float = 10.0) -> np.ndarray:
    """The 36 velocities of the hand in a video file, step by step as the run's video source reads it."""
    from rtcohand_drake.data.hand_features import FEATURE_DIM, HandFeatureStream
    from rtcohand_drake.vision.calibration import CameraCalibration
    from rtcohand_drake.vision.capture import HandPipeline, VideoFileTracker
    from rtcohand_drake.vision.config import Camera

    tracker = VideoFileTracker(path, HandPipeline(CameraCalibration(), Camera()))
    stream, rows = HandFeatureStream(), []
    try:
        for k in range(int(tracker.duration_s * rate_hz)):
            keypoints, _ = tracker.latest(k / rate_hz)
            x, ok = stream.update(keypoints if keypoints is not None else np.full((21, 3), np.nan), k / rate_hz)
            if ok:
                rows.append(x)
    finally:
        tracker.close()
    return np.array(rows, np.float32).reshape(-1, FEATURE_DIM)


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.learning.policy_file import load_policy

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--file", default="models/cchp_path_shape.pt", help="a policy file with fast_turn_share")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--data", help="a generated population or a recorded dataset file")
    what.add_argument("--videos", type=Path, help="a folder of video files of a real hand")
    p.add_argument("--people", nargs="+", default=None, help="recorded people (their split = train clips)")
    p.add_argument("--every", type=int, default=8)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    module = load_policy(args.file)
    if not hasattr(module, "fast_turn_share"):
        raise SystemExit(f"error: {args.file} has no fast_turn_share")
    gate = float(module.min_fast_turns)
    if args.videos is not None:
        files = sorted(f for f in args.videos.iterdir() if f.suffix.lower() in VIDEO_SUFFIXES)
        if not files:
            raise SystemExit(f"error: {args.videos}: no video files")
        pieces = []
        for f in files:
            x = video_features(f)
            pieces.append((x, np.zeros((len(x), 6), np.float32)))
            print(f"{f.name}: {len(x)} steps with a hand, fast turns {share(module, [pieces[-1]]):.3f}", flush=True)
        print(f"all {len(files)} pooled: {share(module, pieces):.3f} (the file's gate: {gate:g})")
    elif args.people:
        from rtcohand_drake.data.dataset import load_policy_clips

        clips = load_policy_clips(args.data, 10.0)
        for person in args.people:
            pieces = [(c.features, c.labels) for c in clips
                      if c.user == person and c.split == "train" and c.labels is not None]
            if not pieces:
                raise SystemExit(f"error: {args.data}: no labelled split = train clips of {person!r}")
            print(f"{person}: fast turns {share(module, pieces):.3f} (the file's gate: {gate:g})", flush=True)
    else:
        from rtcohand_drake.data.sampling import evaluation_episodes
        from rtcohand_drake.learning.train import load_clips

        episodes = evaluation_episodes(load_clips(args.data, 10.0), "Own", 0)[::args.every]
        shares = np.array([share(module, e.context) for e in episodes])
        print(f"{Path(args.data).name}: {len(shares)} Own episodes (every {args.every}th): fast turns min "
              f"{shares.min():.4f}, median {np.median(shares):.4f}, max {shares.max():.4f}; "
              f"{int((shares >= gate).sum())} at the file's gate ({gate:g}) or more")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
