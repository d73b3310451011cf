"""The camera's calibration: intrinsics, and the camera's pose in the user frame U.

A calibration file is YAML, every key optional (the defaults below):

    image_size_px: [640, 480]
    focal_length_px: [554.3, 554.3]    # fx, fy
    principal_point_px: [320.0, 240.0] # cx, cy (default: the image centre)
    distortion: [0, 0, 0, 0, 0]        # OpenCV's k1 k2 p1 p2 k3
    camera_position_m: [0.0, 0.5, 0.1] # the camera's optical centre, in U
    camera_rpy_deg: [-90.0, 0.0, 180.0]  # its frame C (OpenCV: x right, y down, z along the view) in U

The defaults are a webcam of about 60 degrees horizontal field of view, 0.5 m
in front of the person at hand height, facing them (C's z axis along -Y of U,
image right = the person's left). Running without a file uses them and says
so (`DEFAULT_WARNING`): the features then carry the default's error in the
camera's orientation.
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc
import math
from pathlib import Path

import numpy as np

from rtcohand_drake.errors import InputError

DEFAULT_WARNING = ("no --camera-calibration given: using the defaults for a webcam facing the person "
                   "(60 degrees field of view, 0.5 m away at hand height); see docs/own_hand.md")


@dc.dataclass
class CameraCalibration:
    image_size_px: list[int] = dc.field(default_factory=lambda: [640, 480])
    focal_length_px: list[float] = dc.field(default_factory=lambda: [554.3, 554.3])
    # Empty: the image centre.
    principal_point_px: list[float] = dc.field(default_factory=list)
    distortion: list[float] = dc.field(default_factory=lambda: [0.0] * 5)
    camera_position_m: list[float] = dc.field(default_factory=lambda: [0.0, 0.5, 0.1])
    camera_rpy_deg: list[float] = dc.field(default_factory=lambda: [-90.0, 0.0, 180.0])

    def camera_matrix(self, image_size_px=None) -> np.ndarray:
        """K for frames of `image_size_px` (w, h); focal lengths scale with the width."""
        w0, h0 = self.image_size_px
        w, h = image_size_px if image_size_px is not None else (w0, h0)
        s = w / w0
        cx, cy = (self.principal_point_px if self.principal_point_px else (w0 / 2.0, h0 / 2.0))
        fx, fy = self.focal_length_px
        return np.array([[fx * s, 0.0, cx * s], [0.0, fy * s, cy * (h / h0)], [0.0, 0.0, 1.0]])

    def distortion_coefficients(self) -> np.ndarray:
        return np.asarray(self.distortion, float)

    def R_UC(self) -> np.ndarray:
        """The camera frame's axes in U (columns), from roll-pitch-yaw (x, then y, then z, fixed axes)."""
        r, p, y = np.deg2rad(self.camera_rpy_deg)
        Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
        Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
        Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
        return Rz @ Ry @ Rx

    def p_UC(self) -> np.ndarray:
        return np.asarray(self.camera_position_m, float)

    def to_user_frame(self, points_C: np.ndarray) -> np.ndarray:
        """Points (N, 3) from the camera frame into U."""
        return np.asarray(points_C, float) @ self.R_UC().T + self.p_UC()


_LENGTHS = {"image_size_px": (2,), "focal_length_px": (2,), "principal_point_px": (0, 2),
            "distortion": (4, 5, 8, 12, 14), "camera_position_m": (3,), "camera_rpy_deg": (3,)}


def load_calibration(path) -> CameraCalibration:
    """Reads a calibration file (module docstring); a bad file is a one-line InputError naming it."""
    import yaml
    from pydrake.common.yaml import yaml_load_typed

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such camera calibration file")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as err:
        raise InputError(f"{path}: not valid YAML: {err}") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: a camera calibration is a mapping of keys to values")
    unknown = sorted(set(data) - set(_LENGTHS))
    if unknown:
        raise InputError(f"{path}: unknown key {unknown[0]!r} (known: {', '.join(_LENGTHS)})")
    try:
        calib = yaml_load_typed(schema=CameraCalibration, data=yaml.safe_dump(data))
    except RuntimeError as err:
        raise InputError(f"{path}: {err}") from None
    for key, lengths in _LENGTHS.items():
        value = getattr(calib, key)
        if len(value) not in lengths:
            raise InputError(f"{path}: {key} needs {' or '.join(map(str, lengths))} numbers, got {len(value)}")
        if not all(math.isfinite(v) for v in value):
            raise InputError(f"{path}: {key} has a non-finite number")
    if min(calib.image_size_px) <= 0 or min(calib.focal_length_px) <= 0:
        raise InputError(f"{path}: image_size_px and focal_length_px must be positive")
    return calib
