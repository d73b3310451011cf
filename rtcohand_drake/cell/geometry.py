"""Small rotation and easing helpers shared by the cell, the simulated person and the scoring.

Numpy only (no Drake), so the data generator uses them too. Quaternions are
[w x y z], as in the run log's poses (docs/interfaces.md).
"""

from __future__ import annotations

import math

import numpy as np


def vector_norm(x: np.ndarray) -> float:
    """|x| of a 1-D array: numpy's own `linalg.norm` arithmetic (sqrt of x.dot(x)), without its
    dispatch, for the small vectors of the per-period updates."""
    return math.sqrt(x.dot(x))


def all_close(a: np.ndarray, b: np.ndarray) -> bool:
    """`np.allclose(a, b)` (rtol 1e-5, atol 1e-8) for finite arrays, without its dispatch."""
    return bool((np.abs(a - b) <= 1e-8 + 1e-5 * np.abs(b)).all())


def quaternion_to_matrix(wxyz: np.ndarray, normalize: bool = True) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) [w x y z].

    `normalize` rescales each quaternion to unit length first (logged poses);
    the generator's own quaternions are unit already and skip it.
    """
    q = np.asarray(wxyz, float)
    if q.size == 4:  # one quaternion: the same arithmetic on Python floats (a run's monitors call this often)
        return _one_quaternion_to_matrix(q, normalize).reshape(q.shape[:-1] + (3, 3))
    if normalize:
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _one_quaternion_to_matrix(q: np.ndarray, normalize: bool) -> np.ndarray:
    w, x, y, z = (float(c) for c in q.reshape(4))
    if normalize:
        n = float(np.sqrt(w * w + x * x + y * y + z * z))
        w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion [w x y z] of a rotation matrix."""
    from pydrake.math import RotationMatrix

    q = RotationMatrix(R).ToQuaternion()
    return np.array([q.w(), q.x(), q.y(), q.z()])


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (SO(3) logarithm), robust at a half turn."""
    s = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arctan2(np.linalg.norm(s), c)
    if theta < 1e-9:
        return s
    if np.pi - theta < 1e-6:  # half turn: axis from the symmetric part
        axis = np.sqrt(np.maximum(np.diag(R) + 1.0, 0.0) / 2.0)
        k = int(np.argmax(axis))
        axis = (R[:, k] + np.eye(3)[k]) / np.linalg.norm(R[:, k] + np.eye(3)[k])
        return theta * axis
    return s * theta / np.sin(theta)


def smoothstep(x):
    """3x^2 - 2x^3 of x clipped to [0, 1]: an easing from 0 to 1 with zero slope at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)
