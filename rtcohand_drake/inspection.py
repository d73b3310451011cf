"""The inspection task, measured from the workpiece's trajectory.

A face counts as inspected when its outward normal points within
`max_angle_deg` (35 degrees) of the direction from the workpiece centre to
the inspector's eye, continuously for at least `hold_s` (0.5 s). The task is
complete when all six faces have been inspected; its completion time is the
moment the last face's hold is over.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from rtcohand_drake.workpiece_faces import FACES


@dc.dataclass
class InspectionResult:
    inspected_at: dict  # face name -> time (s) its hold completed, or NaN
    faces_inspected: int
    completed: bool
    completion_time: float


def quaternion_to_matrix(wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (K,3,3) from unit quaternions (K,4) [w x y z]."""
    q = np.asarray(wxyz, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def face_angles_deg(poses: np.ndarray, eye_xyz) -> np.ndarray:
    """(K, 6) angle between each face's outward normal and the line of sight to the eye."""
    poses = np.atleast_2d(np.asarray(poses, float))
    R = quaternion_to_matrix(poses[:, 3:7])
    to_eye = np.asarray(eye_xyz, float) - poses[:, :3]
    to_eye /= np.linalg.norm(to_eye, axis=1, keepdims=True)
    normals_E = np.array([face[1] for face in FACES], float)  # (6, 3)
    normals_W = np.einsum("kij,fj->kfi", R, normals_E)
    cos = np.clip(np.einsum("kfi,ki->kf", normals_W, to_eye), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def measure_inspection(times: np.ndarray, poses: np.ndarray, eye_xyz,
                       max_angle_deg: float = 35.0, hold_s: float = 0.5) -> InspectionResult:
    times = np.asarray(times, float)
    inspected_at = {face[0]: float("nan") for face in FACES}
    if len(times):
        visible = face_angles_deg(poses, eye_xyz) <= max_angle_deg
        for f, face in enumerate(FACES):
            start = None
            for k, t in enumerate(times):
                if visible[k, f]:
                    start = t if start is None else start
                    if t - start >= hold_s:
                        inspected_at[face[0]] = float(t)
                        break
                else:
                    start = None
    done = [t for t in inspected_at.values() if np.isfinite(t)]
    completed = len(done) == len(FACES)
    return InspectionResult(inspected_at, len(done), completed, max(done) if completed else float("nan"))
