"""Latency of the camera gesture source, from a captured frame to the gesture features.

    python benchmarks/bench_camera.py [--seconds 10] [--width 640 --height 480] [--out FILE.json]

A drawn-hand video (the stand-in for a webcam, `rtcohand_drake.vision.drawn_hand`)
is written to a temporary file, then read frame by frame as the camera source
reads it. Per frame it times: decoding the frame (what a camera's `read()`
costs here), MediaPipe's landmarks in video mode plus the metric fit into U
(`HandPipeline.process`), and the features the keypoint source computes from
two successive skeletons (`part_frames`, `part_velocities`). Capture to
features is the sum of the last two: the frame is stamped when `read()`
returns it. Wall time depends on what else the machine runs, so the CPU time
the process spends on a frame (all its threads) is reported too, with the
load average at the start. The features are then read at the next policy update, on average
half a policy period later (50 ms at 10 Hz); that wait is not included.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--num-hands", type=int, default=2,
                   help="MediaPipe's num_hands (scenario camera.num_hands): with fewer hands tracked than this "
                        "it runs the palm detector on every frame")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args()
    import cv2

    load = os.getloadavg()[0]

    from rtcohand_drake.data.hand_features import part_frames, part_velocities
    from rtcohand_drake.vision.calibration import CameraCalibration
    from rtcohand_drake.vision.capture import HandPipeline
    from rtcohand_drake.vision.config import Camera
    from rtcohand_drake.vision.drawn_hand import drawn_hand_frames, write_video

    calibration = CameraCalibration(image_size_px=[args.width, args.height],
                                    focal_length_px=[554.3 * args.width / 640] * 2)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hand.avi"
        write_video(path, (f for f, _ in drawn_hand_frames(calibration, [("wave", args.seconds)])))
        capture = cv2.VideoCapture(str(path))
        fps = capture.get(cv2.CAP_PROP_FPS)
        pipeline = HandPipeline(calibration, Camera(num_hands=args.num_hands))
        decode, track, features, cpu, lost = [], [], [], [], 0
        previous = None
        i = 0
        while True:
            t0 = time.perf_counter()
            ok, frame = capture.read()
            t1 = time.perf_counter()
            if not ok:
                break
            c1 = time.process_time()
            keypoints = pipeline.process(frame, i / fps)
            t2 = time.perf_counter()
            if keypoints is None:
                lost += 1
                previous = None
            else:
                R1, o1 = part_frames(keypoints)
                if previous is not None:
                    part_velocities(*previous, R1, o1, 1.0 / fps)
                previous = (R1, o1)
            t3 = time.perf_counter()
            cpu.append(time.process_time() - c1)
            decode.append(t1 - t0)
            track.append(t2 - t1)
            features.append(t3 - t2)
            i += 1
        capture.release()
        pipeline.close()
    ms = lambda x: {"median": float(np.median(x) * 1e3), "p95": float(np.percentile(x, 95) * 1e3)}
    total = np.asarray(track) + np.asarray(features)
    result = {"frames": i, "num_hands": args.num_hands, "frames_without_hand": lost, "width": args.width, "height": args.height,
              "decode_ms": ms(decode), "landmarks_and_fit_ms": ms(track), "features_ms": ms(features),
              "capture_to_features_ms": ms(total), "capture_to_features_cpu_ms": ms(cpu),
              "cpu_threads": len(os.sched_getaffinity(0)), "load_average_1min": load}
    print(json.dumps(result, indent=2))
    if args.out is not None:
        args.out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
