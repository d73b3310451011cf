"""ArUco marker pose from rendered images of a known pose, and the twist from a pose sequence."""

import cv2
import numpy as np
import pytest

from rtcohand_drake.vision.aruco import MarkerConfig, MarkerTracker, twist_in_user_frame

K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
LENGTH = 0.05


def _rotation(rx_deg, ry_deg, rz_deg):
    return cv2.Rodrigues(np.deg2rad([rx_deg, 0.0, 0.0]))[0] @ cv2.Rodrigues(np.deg2rad([0.0, ry_deg, 0.0]))[0] \
        @ cv2.Rodrigues(np.deg2rad([0.0, 0.0, rz_deg]))[0]


def render_marker(R_CM, p_CM, side_px=400, marker_id=0):
    """A 640 x 480 image of the 50 mm marker (a white quiet zone around it) at pose (R_CM, p_CM)."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    marker = cv2.aruco.generateImageMarker(dictionary, marker_id, side_px)
    border = side_px // 4
    sheet = cv2.copyMakeBorder(marker, border, border, border, border, cv2.BORDER_CONSTANT, value=255)
    # Sheet pixel (u, v) -> marker-frame point (x, y, 0): the marker's y axis points up.
    m = LENGTH / side_px
    S = np.array([[m, 0.0, -(border + side_px / 2) * m], [0.0, -m, (border + side_px / 2) * m], [0.0, 0.0, 1.0]])
    H = K @ np.column_stack([R_CM[:, 0], R_CM[:, 1], p_CM]) @ S
    image = cv2.warpPerspective(cv2.cvtColor(sheet, cv2.COLOR_GRAY2BGR), H, (640, 480), flags=cv2.INTER_AREA,
                                borderValue=(90, 90, 90))
    return image


POSES = [((0, 0, 0), (0.0, 0.0, 0.30)), ((25, 0, 10), (0.03, -0.02, 0.40)),
         ((-20, 30, -15), (-0.05, 0.03, 0.50)), ((10, -25, 40), (0.02, 0.04, 0.60))]


@pytest.mark.parametrize("refinement, mm, deg", [("APRILTAG", 2.0, 1.0), ("SUBPIX", 6.0, 2.0)])
def test_marker_pose_from_rendered_images(refinement, mm, deg):
    tracker = MarkerTracker(MarkerConfig(refinement=refinement))
    for angles, p in POSES:
        R_true, p_true = _rotation(*angles), np.array(p)
        # Face the camera: the marker's z axis points back at it.
        R_true = R_true @ cv2.Rodrigues(np.array([np.pi, 0.0, 0.0]))[0]
        found = tracker.pose_in_camera(render_marker(R_true, p_true), K)
        assert found is not None, angles
        R, t = found
        assert np.linalg.norm(t - p_true) * 1e3 < mm, (angles, t - p_true)
        angle = np.degrees(np.arccos(np.clip((np.trace(R.T @ R_true) - 1) / 2, -1, 1)))
        assert angle < deg, (angles, angle)


def test_other_marker_or_none_is_not_found():
    tracker = MarkerTracker(MarkerConfig(marker_id=3))
    R = cv2.Rodrigues(np.array([np.pi, 0.0, 0.0]))[0]
    assert tracker.pose_in_camera(render_marker(R, np.array([0.0, 0.0, 0.4])), K) is None
    assert tracker.pose_in_camera(np.full((480, 640, 3), 90, np.uint8), K) is None


def test_twist_from_poses():
    t = np.arange(0.0, 1.0, 1 / 30)
    w, v = np.array([0.0, 0.0, 0.5]), np.array([0.1, -0.05, 0.02])
    R = np.stack([cv2.Rodrigues(w * s)[0] for s in t])
    p = np.outer(t, v)
    twist = twist_in_user_frame(t, R, p)
    assert np.allclose(twist[:, :3], v, atol=1e-9) and np.allclose(twist[:, 3:], w, atol=1e-6)
    p[10] = np.nan
    twist = twist_in_user_frame(t, R, p)
    assert np.all(np.isnan(twist[[9, 11]])) and np.all(np.isfinite(twist[12]))


@pytest.mark.parametrize("marker_rpy_deg", [[60.0, 0.0, 160.0], [70.0, 15.0, 200.0]])
def test_calibrate_command_recovers_the_camera_pose(tmp_path, marker_rpy_deg):
    """A marker drawn, tilted, where the default webcam would see it gives back the default camera pose."""
    from rtcohand_drake.vision.calibrate import main as calibrate, rpy_deg
    from rtcohand_drake.vision.calibration import CameraCalibration, load_calibration

    truth = CameraCalibration()
    R_UM = CameraCalibration(camera_rpy_deg=marker_rpy_deg).R_UC()  # the same roll-pitch-yaw convention
    p_UM = np.array([0.02, 0.2, 0.05])
    R_CM = truth.R_UC().T @ R_UM
    p_CM = truth.R_UC().T @ (p_UM - truth.p_UC())
    assert R_CM[2, 2] < -0.7  # the marker faces the camera
    global K
    K_saved, K = K, truth.camera_matrix()
    try:
        image = render_marker(R_CM, p_CM)
    finally:
        K = K_saved
    path = tmp_path / "marker.png"
    cv2.imwrite(str(path), image)
    out = tmp_path / "cam.yaml"
    assert calibrate(["--out", str(out), "--image", str(path), "--marker-position-m", *map(str, p_UM),
                      "--marker-rpy-deg", *map(str, marker_rpy_deg)]) == 0
    got = load_calibration(out)
    assert np.linalg.norm(got.p_UC() - truth.p_UC()) < 0.005
    angle = np.degrees(np.arccos(np.clip((np.trace(got.R_UC().T @ truth.R_UC()) - 1) / 2, -1, 1)))
    assert angle < 1.0
    # rpy_deg inverts the calibration's own convention.
    assert np.allclose(CameraCalibration(camera_rpy_deg=rpy_deg(R_UM)).R_UC(), R_UM, atol=1e-9)


def test_calibrate_without_a_marker_is_one_line(tmp_path):
    from rtcohand_drake.vision.calibrate import main as calibrate

    path = tmp_path / "empty.png"
    cv2.imwrite(str(path), np.full((480, 640, 3), 90, np.uint8))
    from rtcohand_drake.errors import InputError

    with pytest.raises(InputError, match="no ArUco marker 0") as err:
        calibrate(["--out", str(tmp_path / "cam.yaml"), "--image", str(path)])
    assert str(path) in str(err.value)
