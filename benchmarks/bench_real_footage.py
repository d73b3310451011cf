"""Real footage: how steady the tracked hand is in depth, and the depth filter's lag.

    python benchmarks/bench_real_footage.py --clips DIR [--rate-hz 10] [--out FILE.json]

DIR holds video files (any OpenCV reads: .gif, .mp4, .avi) of a person
gesturing; nothing derived from them is written but the figures. Each clip
goes through MediaPipe once as the code was before the depth filter (no
blur) and once with the scenario's camera settings, every frame, as the live
camera tracker sees them; the camera is unknown, so the default calibration
(`CameraCalibration()`, focal length scaled to the clip's width) places the
hand in U. Then each candidate below turns the same detections into the
palm's path in U (the palm part's origin, `part_frames`), and per clip:

- tracked: the share of frames with a hand;
- the 5th-95th percentile range of the palm along X, Y (depth) and Z of U;
- ratio: the depth range over the range along the swipe, for a clip named
  `*left_right*` (X) or `*up_down*` (Z); the target is <= 0.5;
- the median speed of the palm in depth from frame to frame (m/s): the
  jitter the policy would read as a Ty command.

At the policy's rate: the same figures for the code before and the default,
with each clip played as `--video` plays it (`VideoFileTracker` polled at
`--rate-hz`, so MediaPipe sees only the frames the policy asks for), through
`HandPipeline`, the run's own path.

Lag: a synthetic hand (the project's hand model, 0.3 m from the camera) moves
0.10 m in depth, as a step and as a 0.3 s smooth move, sampled at `--rate-hz`
(the policy's rate); the lag is how much later the filtered depth crosses
half the move than the unfiltered one (`depth_lag_s`).
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
from pathlib import Path

import numpy as np

VIDEO_SUFFIXES = (".gif", ".mp4", ".avi", ".mov", ".mkv", ".webm")


def candidates():
    """Name -> (blur the frames, PoseFilter): the code before, each piece alone, and the combinations."""
    from rtcohand_drake.vision.config import Camera, PoseFilter

    default = Camera().pose_filter
    off = PoseFilter(enabled=False)
    alone = dict(smoother="none", max_depth_speed_m_s=1e9)  # no smoothing, no jump rejection
    return {
        "before (no blur, no filter)": (False, off),
        "blur only": (True, off),
        "jump rejection": (True, dc.replace(default, depth_cue="fit", smoother="none")),
        "One Euro": (True, dc.replace(default, depth_cue="fit", max_depth_speed_m_s=1e9)),
        "Kalman": (True, dc.replace(default, depth_cue="fit", smoother="kalman", max_depth_speed_m_s=1e9)),
        "fixed palm size": (True, dc.replace(default, depth_cue="fixed_palm", **alone)),
        "fixed palm size + One Euro + jumps": (True, dc.replace(default, depth_cue="fixed_palm")),
        "palm spans": (True, dc.replace(default, **alone)),
        "palm spans + jumps": (True, dc.replace(default, smoother="none")),
        "palm spans + Kalman + jumps": (True, dc.replace(default, smoother="kalman")),
        "palm spans + One Euro + jumps (default)": (True, default),
    }


def detect_clip(path: Path, camera) -> list:
    """Per frame: (time s, (width, height), the followed hand's detection or None)."""
    import cv2

    from rtcohand_drake.vision.hand_pose import choose_hand
    from rtcohand_drake.vision.landmarker import HandLandmarker

    capture = cv2.VideoCapture(str(path))
    fps = capture.get(cv2.CAP_PROP_FPS)
    if not capture.isOpened() or not fps > 0:
        raise SystemExit(f"{path}: cannot read it as a video with a frame rate")
    frames = []
    with HandLandmarker(camera, video=True) as landmarker:
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            t = len(frames) / fps
            h, w = frame.shape[:2]
            frames.append((t, (w, h), choose_hand(landmarker.detect(frame, t), camera)))
    capture.release()
    if not frames:
        raise SystemExit(f"{path}: no frames")
    return frames


def palm_path(frames, pose_filter) -> tuple[np.ndarray, np.ndarray]:
    """The frame times (n_tracked,) and the palm's origin in U (n_tracked, 3) through a fresh `HandPoseFilter`."""
    from rtcohand_drake.data.hand_features import part_frames
    from rtcohand_drake.vision.calibration import CameraCalibration
    from rtcohand_drake.vision.hand_pose import keypoints_in_camera
    from rtcohand_drake.vision.hand_pose_filter import HandPoseFilter

    calibration = CameraCalibration()
    steady = HandPoseFilter(pose_filter)
    times, palms = [], []
    for t, size, hand in frames:
        if hand is None:
            continue
        K = calibration.camera_matrix(size)
        points_C = keypoints_in_camera(hand, K)
        if points_C is None:
            continue
        points_U = calibration.to_user_frame(steady.steady(hand, points_C, K, t))
        times.append(t)
        palms.append(part_frames(points_U)[1][0])
    return np.array(times), np.array(palms).reshape(-1, 3)


def policy_rate_path(path: Path, camera, rate_hz: float) -> tuple[list, np.ndarray, np.ndarray]:
    """The clip as the run's video source reads it: per policy step whether a hand was seen; the times
    and palm origins in U of the steps with one."""
    from rtcohand_drake.data.hand_features import part_frames
    from rtcohand_drake.vision.calibration import CameraCalibration
    from rtcohand_drake.vision.capture import HandPipeline, VideoFileTracker

    tracker = VideoFileTracker(path, HandPipeline(CameraCalibration(), camera))
    steps, times, palms = [], [], []
    try:
        for k in range(int(tracker.duration_s * rate_hz)):
            keypoints, t = tracker.latest(k / rate_hz)
            steps.append(keypoints is not None)
            if keypoints is not None:
                times.append(t)
                palms.append(part_frames(keypoints)[1][0])
    finally:
        tracker.close()
    return steps, np.array(times), np.array(palms).reshape(-1, 3)


def swipe_axis(name: str) -> int | None:
    return 0 if "left_right" in name else 2 if "up_down" in name else None


def clip_figures(name: str, frames, times: np.ndarray, palms: np.ndarray) -> dict:
    spread = lambda x: float(np.percentile(x, 95) - np.percentile(x, 5)) if len(x) else float("nan")
    ranges = [spread(palms[:, k]) for k in range(3)]
    axis = swipe_axis(name)
    depth_speed = np.abs(np.diff(palms[:, 1])) / np.diff(times) if len(times) > 1 else np.array([np.nan])
    return {"frames": len(frames), "tracked": len(palms) / len(frames),
            "x_range_m": ranges[0], "depth_range_m": ranges[1], "z_range_m": ranges[2],
            "depth_speed_median_m_s": float(np.median(depth_speed)),
            "swipe_axis": "XYZ"[axis] if axis is not None else None,
            "depth_over_swipe": ranges[1] / ranges[axis] if axis is not None else None}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--clips", type=Path, required=True, help="a folder of video files")
    p.add_argument("--rate-hz", type=float, default=10.0, help="the rate the lag is measured at")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args()

    from rtcohand_drake.vision.config import Camera, PoseFilter
    from rtcohand_drake.vision.hand_pose_filter import depth_lag_s

    paths = sorted(q for q in args.clips.iterdir() if q.suffix.lower() in VIDEO_SUFFIXES)
    if not paths:
        raise SystemExit(f"{args.clips}: no video files")
    detections = {blur: {q.stem: detect_clip(q, Camera() if blur else Camera(blur_sigma_px=0.0)) for q in paths}
                  for blur in (False, True)}
    results = {"clips": [q.name for q in paths], "candidates": {}}
    for label, (blur, pose_filter) in candidates().items():
        per_clip = {name: clip_figures(name, frames, *palm_path(frames, pose_filter))
                    for name, frames in detections[blur].items()}
        lag = {kind: depth_lag_s(pose_filter, args.rate_hz, rise_s) for kind, rise_s in (("step", 0.0), ("smooth_0.3s", 0.3))}
        results["candidates"][label] = {"pose_filter": dc.asdict(pose_filter), "blur": blur, "clips": per_clip,
                                        "lag_ms": {k: v * 1e3 for k, v in lag.items()}}
    results["policy_rate"] = {}
    for label, camera in (("before (no blur, no filter)", Camera(blur_sigma_px=0.0, pose_filter=PoseFilter(enabled=False))),
                          ("default", Camera())):
        per_clip = {}
        for q in paths:
            steps, times, palms = policy_rate_path(q, camera, args.rate_hz)
            per_clip[q.stem] = clip_figures(q.stem, steps, times, palms)
        results["policy_rate"][label] = per_clip
    for label, r in [*results["candidates"].items(), *((f"at {args.rate_hz:g} Hz, {k}", {"clips": v})
                                                       for k, v in results["policy_rate"].items())]:
        lag = r.get("lag_ms")
        print(f"\n{label}" + (f": lag {lag['step']:.0f} ms (step), {lag['smooth_0.3s']:.0f} ms (0.3 s move)" if lag else ""))
        print(f"  {'clip':20s} tracked  X(m)   Y(m)   Z(m)  Y/swipe  |dY/dt|(m/s)")
        for name, c in r["clips"].items():
            ratio = "" if c["depth_over_swipe"] is None else f"{c['depth_over_swipe']:.2f}"
            print(f"  {name:20s} {c['tracked']:6.2f} {c['x_range_m']:6.3f} {c['depth_range_m']:6.3f} "
                  f"{c['z_range_m']:6.3f}  {ratio:7s}  {c['depth_speed_median_m_s']:.2f}")
    if args.out is not None:
        args.out.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
