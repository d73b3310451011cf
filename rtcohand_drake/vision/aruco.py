"""An ArUco-marked object's pose from a camera image, and its twist in the user frame.

The paper's labels came from a handler moving an ArUco-tracked object; the
recorder's `--labels aruco` does the same. `MarkerTracker.pose_in_camera`
finds the marker (`cv2.aruco.ArucoDetector`) and solves its pose with
`cv2.solvePnP(..., SOLVEPNP_IPPE_SQUARE)`: the marker frame M has its origin
at the marker's centre, x to the right and y up across the printed marker,
z out of its face, which sets the corner order (top-left, top-right,
bottom-right, bottom-left). `twist_in_user_frame` differentiates a sequence
of poses in U into `[vx vy vz wx wy wz]` (the object's centre, turning about
itself), the labels of the gesture dataset.

Corner refinement: APRILTAG (the default: labels want precision) is within
2 mm and 1 degree on rendered 50 mm markers at 0.3-0.6 m and up to 40 degrees
of tilt (tests/test_aruco.py), at about 110 ms a frame; SUBPIX within 6 mm
and 2 degrees at about 2.5 ms.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np


@dc.dataclass
class MarkerConfig:
    marker_length_m: float = 0.05  # the printed marker's side, its black border included
    dictionary: str = "DICT_4X4_50"
    marker_id: int = 0
    refinement: str = "APRILTAG"  # NONE | SUBPIX | CONTOUR | APRILTAG


def marker_corners_M(length_m: float) -> np.ndarray:
    """The four corners (4, 3) in the marker frame, in OpenCV's order (top-left first, clockwise)."""
    h = length_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


class MarkerTracker:
    def __init__(self, config: MarkerConfig | None = None):
        import cv2

        self.config = config or MarkerConfig()
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.config.dictionary))
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = getattr(cv2.aruco, f"CORNER_REFINE_{self.config.refinement}")
        self._detector = cv2.aruco.ArucoDetector(dictionary, params)
        self._object = marker_corners_M(self.config.marker_length_m)

    def pose_in_camera(self, image_bgr: np.ndarray, camera_matrix, distortion=None):
        """(R_CM (3, 3), p_CM (3,)) of the configured marker, or None when it is not seen."""
        import cv2

        corners, ids, _ = self._detector.detectMarkers(image_bgr)
        if ids is None:
            return None
        match = [c for c, i in zip(corners, ids.reshape(-1)) if int(i) == self.config.marker_id]
        if not match:
            return None
        dist = np.zeros(5) if distortion is None else np.asarray(distortion, float)
        ok, rvec, tvec = cv2.solvePnP(self._object, match[0].reshape(4, 2).astype(np.float64),
                                      np.asarray(camera_matrix, float), dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            return None
        return cv2.Rodrigues(rvec)[0], tvec.reshape(3)


def twist_in_user_frame(times: np.ndarray, R_UM: np.ndarray, p_UM: np.ndarray) -> np.ndarray:
    """Twists (N, 6) from poses in U (central differences; one-sided at the ends); NaN where a pose is."""
    from rtcohand_drake.data.hand_features import rotation_log

    t = np.asarray(times, float)
    n = len(t)
    out = np.full((n, 6), np.nan)
    for k in range(n):
        a, b = max(k - 1, 0), min(k + 1, n - 1)
        if b == a or not (np.all(np.isfinite(p_UM[[a, b]])) and np.all(np.isfinite(R_UM[[a, b]]))):
            continue
        dt = t[b] - t[a]
        out[k, :3] = (p_UM[b] - p_UM[a]) / dt
        out[k, 3:] = rotation_log(R_UM[b] @ R_UM[a].T) / dt  # angular velocity, expressed in U
    return out
