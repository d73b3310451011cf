"""A Meshcat animation of a clip: the hand skeleton beside the workpiece the handler moved.

Used by the notebooks::

    from pydrake.geometry import Meshcat
    meshcat = Meshcat()
    animate_clip(meshcat, clip)          # then press play in the Meshcat "animation" panel

The hand is drawn in the user frame U (keypoints as spheres, bones as
cylinders); the workpiece is a box whose pose integrates the clip's
``object_velocity`` (a twist in U: the box's centre moves with v and the box
turns about its centre with w, docs/interfaces.md (frames and the meaning of a twist)), placed ``box_offset_m`` to the
side of the hand's first position. A frame where the hand was lost keeps the
last seen hand. pydrake is imported inside the function, so this module loads
without Drake.
"""

from __future__ import annotations

import numpy as np

from rtcohand_drake.data.dataset import Clip
from rtcohand_drake.data.population import integrate_pose
from rtcohand_drake.data.hand_features import FINGER_CHAINS

BONES = [(0, int(c[0])) for c in FINGER_CHAINS] + [
    (int(c[i]), int(c[i + 1])) for c in FINGER_CHAINS for i in range(3)
] + [(5, 9), (9, 13), (13, 17)]


def _bone_rotation(direction: np.ndarray) -> np.ndarray:
    """A rotation taking +Z to the unit vector ``direction`` (cylinders lie along Z)."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def animate_clip(
    meshcat,
    clip: Clip,
    prefix: str = "gesture_clip",
    box_size_m: tuple[float, float, float] = (0.12, 0.08, 0.05),
    box_offset_m: tuple[float, float, float] = (0.3, 0.0, 0.0),
    publish: bool = True,
):
    """Record an animation of ``clip`` into ``meshcat`` and return the MeshcatAnimation."""
    from pydrake.geometry import Box, Cylinder, Rgba, Sphere
    from pydrake.math import RigidTransform, RotationMatrix
    from pydrake.common.eigen_geometry import Quaternion

    kp = np.asarray(clip.keypoints, dtype=np.float64)
    seen = np.isfinite(kp).all(axis=(1, 2))
    if not seen.any():
        raise ValueError(f"clip {clip.name} never sees the hand")
    # Fill lost frames with the last seen hand (the first seen one before any).
    filled = kp.copy()
    last = kp[np.argmax(seen)]
    for i in range(kp.shape[0]):
        if seen[i]:
            last = kp[i]
        else:
            filled[i] = last
    lengths = np.median(np.linalg.norm(filled[:, [a for a, _ in BONES]] - filled[:, [b for _, b in BONES]], axis=2), axis=0)

    times = clip.times - clip.times[0]
    velocity = clip.object_velocity if clip.object_velocity is not None else np.zeros((kp.shape[0], 6))
    dt = float(np.median(np.diff(times))) if times.size > 1 else 1.0 / clip.fps
    start = filled[0, 0] + np.asarray(box_offset_m)
    pose = integrate_pose(start, np.asarray(velocity, dtype=np.float64), dt)

    meshcat.Delete(prefix)
    for j in range(21):
        meshcat.SetObject(f"{prefix}/hand/k{j}", Sphere(0.006), Rgba(0.2, 0.4, 0.9, 1.0))
    for n, length in enumerate(lengths):
        meshcat.SetObject(f"{prefix}/hand/b{n}", Cylinder(0.003, float(max(length, 1e-3))), Rgba(0.3, 0.3, 0.3, 1.0))
    meshcat.SetObject(f"{prefix}/workpiece", Box(*box_size_m), Rgba(0.85, 0.55, 0.2, 1.0))

    meshcat.StartRecording(frames_per_second=float(clip.fps), set_visualizations_while_recording=False)
    for i, t in enumerate(times):
        hand = filled[i]
        for j in range(21):
            meshcat.SetTransform(f"{prefix}/hand/k{j}", RigidTransform(hand[j]), float(t))
        for n, (a, b) in enumerate(BONES):
            d = hand[b] - hand[a]
            if np.linalg.norm(d) < 1e-9:
                continue
            X = RigidTransform(RotationMatrix(_bone_rotation(d)), 0.5 * (hand[a] + hand[b]))
            meshcat.SetTransform(f"{prefix}/hand/b{n}", X, float(t))
        q = pose[i, 3:] / np.linalg.norm(pose[i, 3:])
        X_box = RigidTransform(Quaternion(q[0], q[1], q[2], q[3]), pose[i, :3])
        meshcat.SetTransform(f"{prefix}/workpiece", X_box, float(t))
    meshcat.StopRecording()
    if publish:
        meshcat.PublishRecording()
    return meshcat.get_mutable_recording()
