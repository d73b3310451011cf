"""`python -m rtcohand_drake.vision.calibrate`: the camera's pose in the user frame from one ArUco marker.

    python -m rtcohand_drake.vision.calibrate --out cam.yaml (--camera N | --image PATH)
        [--intrinsics FILE] [--marker-position-m X Y Z] [--marker-rpy-deg R P Y]
        [--marker-length-m 0.05] [--marker-id 0]

A one-time guided step: hold (or stand) a printed ArUco marker (DICT_4X4_50,
id 0, 50 mm with its black border) where your hand will gesture, flat and
upright facing the camera, its top edge up: by default 0.0 m right, 0.2 m
forward and 0.0 m up of the user frame's origin, its face toward the camera
in front of you (marker frame: x to your left, y up, z toward the camera,
which is roll-pitch-yaw [90, 0, 180] in U). A marker facing the camera
squarely gives the least well-conditioned fit (about 2 degrees off on a
drawn image); tilted back by about 30 degrees (say `--marker-rpy-deg 60 0
180`) it is within 1 degree and 5 mm (tests/test_aruco.py). The command finds the marker
(`rtcohand_drake.vision.aruco`), solves X_CM, and writes
X_UC = X_UM X_CM^-1 with the intrinsics (from `--intrinsics`, a calibration
file whose camera_matrix keys are kept, else the defaults) as a calibration
file for `--camera-calibration` (`rtcohand_drake.vision.calibration`). A live
camera is read for up to 5 s until the marker is seen in 10 frames; their
poses are averaged.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.errors import InputError, non_negative_int, run_cli
from rtcohand_drake.vision.calibration import CameraCalibration, load_calibration


def rpy_deg(R: np.ndarray) -> list[float]:
    """Roll-pitch-yaw (deg, x then y then z, fixed axes) of a rotation: the inverse of `CameraCalibration.R_UC`."""
    pitch = math.asin(-max(-1.0, min(1.0, R[2, 0])))
    roll = math.atan2(R[2, 1], R[2, 2])
    yaw = math.atan2(R[1, 0], R[0, 0])
    return [math.degrees(a) for a in (roll, pitch, yaw)]


def camera_pose_from_marker(R_CM, p_CM, R_UM, p_UM) -> tuple[np.ndarray, np.ndarray]:
    """X_UC = X_UM X_CM^-1: (R_UC, p_UC)."""
    R_UC = R_UM @ R_CM.T
    return R_UC, p_UM - R_UC @ p_CM


def _average_rotation(Rs) -> np.ndarray:
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    R = U @ Vt
    return R if np.linalg.det(R) > 0 else U @ np.diag([1, 1, -1]) @ Vt


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.vision.calibrate", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True,
                   help="the calibration file to write (YAML), for --camera-calibration of run and record")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--camera", type=non_negative_int, help="a live camera (OpenCV camera number), read for up to 5 s")
    src.add_argument("--image", type=Path, help="one image of the marker from the camera, instead of a live camera")
    p.add_argument("--intrinsics", type=Path, default=None,
                   help="a calibration file whose intrinsics (image size, focal length, principal point, "
                        "distortion) are kept (default: a 60-degree webcam's)")
    p.add_argument("--marker-position-m", type=float, nargs=3, default=[0.0, 0.2, 0.0], metavar=("X", "Y", "Z"),
                   help="where the marker's centre is in the user frame, metres (X right, Y forward, Z up; "
                        "default 0 0.2 0)")
    p.add_argument("--marker-rpy-deg", type=float, nargs=3, default=[90.0, 0.0, 180.0], metavar=("R", "P", "Y"),
                   help="the marker's roll-pitch-yaw in the user frame, degrees (default 90 0 180: upright, "
                        "facing the camera in front of you; 60 0 180 tilts it back by 30 degrees)")
    p.add_argument("--marker-length-m", type=float, default=0.05,
                   help="the marker's side, black border included, metres (default 0.05)")
    p.add_argument("--marker-id", type=int, default=0, help="the marker's id in DICT_4X4_50 (default 0)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    import cv2
    import yaml

    args = make_parser().parse_args(argv)
    from rtcohand_drake.vision.aruco import MarkerConfig, MarkerTracker

    calib = load_calibration(args.intrinsics) if args.intrinsics is not None else CameraCalibration()
    tracker = MarkerTracker(MarkerConfig(marker_length_m=args.marker_length_m, marker_id=args.marker_id))
    poses = []
    if args.image is not None:
        image = cv2.imread(str(args.image))
        if image is None:
            raise InputError(f"{args.image}: not a readable image")
        frames = [image]
    else:
        from rtcohand_drake.vision.capture import open_capture

        capture = open_capture(args.camera, f"camera {args.camera}")
        frames = []
        print("hold the marker still where your hand will gesture ...", flush=True)
    import time

    start = time.monotonic()
    while True:
        if args.image is None:
            ok, frame = capture.read()
            if not ok or time.monotonic() - start > 5.0 or len(poses) >= 10:
                break
        else:
            if not frames:
                break
            frame = frames.pop()
        h, w = frame.shape[:2]
        found = tracker.pose_in_camera(frame, calib.camera_matrix((w, h)), calib.distortion_coefficients())
        if found is not None:
            poses.append(found)
    if args.image is None:
        capture.release()
    if not poses:
        raise InputError(f"{args.image if args.image is not None else f'camera {args.camera}'}: "
                         f"no ArUco marker {args.marker_id} (DICT_4X4_50) seen")
    R_CM = _average_rotation([R for R, _ in poses])
    p_CM = np.mean([t for _, t in poses], axis=0)
    R_UM = CameraCalibration(camera_rpy_deg=list(args.marker_rpy_deg)).R_UC()  # the same rpy convention
    R_UC, p_UC = camera_pose_from_marker(R_CM, p_CM, R_UM, np.asarray(args.marker_position_m, float))
    out = {"image_size_px": [int(w), int(h)],
           "focal_length_px": [float(v) for v in np.diag(calib.camera_matrix((w, h)))[:2]],
           "principal_point_px": [float(v) for v in calib.camera_matrix((w, h))[:2, 2]],
           "distortion": [float(v) for v in calib.distortion],
           "camera_position_m": [round(float(v), 4) for v in p_UC],
           "camera_rpy_deg": [round(v, 2) for v in rpy_deg(R_UC)]}
    args.out.write_text("# written by python -m rtcohand_drake.vision.calibrate\n" + yaml.safe_dump(out))
    print(f"marker seen in {len(poses)} frame(s), {np.linalg.norm(p_CM):.3f} m from the camera; "
          f"camera at {out['camera_position_m']} m, rpy {out['camera_rpy_deg']} deg in U; wrote {args.out}")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.vision.calibrate"))


if __name__ == "__main__":
    entry_point()
