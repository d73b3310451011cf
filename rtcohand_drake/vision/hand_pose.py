"""From MediaPipe's landmarks to 21 keypoints in metres in the user frame, and which hand to follow.

MediaPipe's metric world landmarks are centred on the hand: they carry its
shape and orientation but no position. `keypoints_in_camera` fits them to the
image landmarks with the camera's intrinsics (`cv2.solvePnP`, SQPnP), which
gives the rigid motion that places the metric hand in the camera frame;
`CameraCalibration.to_user_frame` then maps it into U.

Which hand, when several are seen (`choose_hand`): the person's right hand,
the one every gesture of this project is made with. MediaPipe labels
handedness for a mirrored (selfie) image, so in a camera image that is not
mirrored the person's right hand is the one labelled "Left"
(the scenario's `camera.mirrored` flips this; `camera.hand` picks the hand). Of several such hands, or when none is
labelled right, the largest in the image, the one nearest the camera, wins.
"""

from __future__ import annotations

import numpy as np

from rtcohand_drake.vision.calibration import CameraCalibration
from rtcohand_drake.vision.config import Camera
from rtcohand_drake.vision.landmarker import HandDetection


def is_persons(detection: HandDetection, hand: str, mirrored: bool) -> bool:
    """Whether MediaPipe's label names the person's `hand` ("right" or "left")."""
    label = detection.handedness.lower()
    own = label if mirrored else {"left": "right", "right": "left"}.get(label, label)
    return own == hand


def choose_hand(detections: list[HandDetection], config: Camera | None = None) -> HandDetection | None:
    """The hand to follow (module docstring), or None when no hand is seen."""
    if not detections:
        return None
    config = config or Camera()
    candidates = detections
    if config.hand in ("right", "left"):
        candidates = [d for d in detections if is_persons(d, config.hand, config.mirrored)] or detections
    return max(candidates, key=lambda d: d.size_px)


def keypoints_in_camera(detection: HandDetection, camera_matrix: np.ndarray,
                        distortion: np.ndarray | None = None) -> np.ndarray | None:
    """The 21 keypoints (21, 3) in metres in the camera frame, or None when the fit fails or lands behind."""
    import cv2

    world = np.ascontiguousarray(detection.world_m, dtype=np.float64)
    image = np.ascontiguousarray(detection.image_px, dtype=np.float64)
    dist = np.zeros(5) if distortion is None else np.asarray(distortion, float)
    ok, rvec, tvec = cv2.solvePnP(world, image, np.asarray(camera_matrix, float), dist, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    R, _ = cv2.Rodrigues(rvec)
    points = world @ R.T + tvec.reshape(1, 3)
    if not (np.all(np.isfinite(points)) and np.all(points[:, 2] > 0.0)):
        return None
    return points


def keypoints_in_user_frame(detection: HandDetection, calibration: CameraCalibration,
                            image_size_px) -> np.ndarray | None:
    """The 21 keypoints (21, 3) in metres in U, or None (see `keypoints_in_camera`)."""
    points_C = keypoints_in_camera(detection, calibration.camera_matrix(image_size_px),
                                   calibration.distortion_coefficients())
    return None if points_C is None else calibration.to_user_frame(points_C)
