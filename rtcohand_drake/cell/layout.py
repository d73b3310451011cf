"""The cell layout and the arm's settings: the `cell` and `robot` keys of a scenario.

Units: metres, degrees where a name says so (`rpy_deg`), radians otherwise.
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc

import numpy as np


@dc.dataclass
class Pose:
    """A rigid transform: translation (m) and roll-pitch-yaw (degrees)."""

    xyz: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])
    rpy_deg: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])

    def to_rigid_transform(self):
        from pydrake.math import RigidTransform, RollPitchYaw

        return RigidTransform(RollPitchYaw(np.deg2rad(self.rpy_deg)), np.asarray(self.xyz, float))


@dc.dataclass
class Box:
    """An axis-aligned box in the world frame (m)."""

    min_xyz: list[float] = dc.field(default_factory=lambda: [-1.0, -1.0, 0.0])
    max_xyz: list[float] = dc.field(default_factory=lambda: [1.0, 1.0, 1.0])

    def contains(self, p) -> bool:
        p = np.asarray(p, float)
        return bool(np.all(p >= self.min_xyz) and np.all(p <= self.max_xyz))


@dc.dataclass
class Cell:
    """Where things stand, all in the world frame (origin: robot base on the table top)."""

    # Table top at z = 0; the table model's frame is on its top surface.
    table: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 0.15, 0.0]))
    # Mold frame: centre of the cavity floor (the mold's floor slab is 0.03 m thick).
    mold: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.45, -0.12, 0.03]))
    # Safety glass panel: bottom centre of the panel.
    safety_glass: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 0.52, 0.0]))
    # The inspector model's frame: on the floor below the eyes, x to the inspector's
    # right, y forward. Its `eye` frame (1.6 m up) is the eye point of the inspection measure.
    inspector: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 1.0, -0.74], rpy_deg=[0, 0, 180]))
    # The user frame U (docs/interfaces.md) in the world: X to the inspector's right, Y away
    # from the inspector toward the robot, Z up.
    user_frame: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 1.0, 0.86], rpy_deg=[0, 0, 180]))


@dc.dataclass
class Robot:
    # Arm joint angles at start (rad): the workpiece rests in the mold.
    q0_rad: list[float] = dc.field(default_factory=lambda: [0.0] * 7)
    # Joint-space PD gains of the simulated arm's position-velocity servo.
    kp_nm_per_rad: list[float] = dc.field(default_factory=lambda: [2000.0] * 4 + [500.0] * 3)
    kd_nm_s_per_rad: list[float] = dc.field(default_factory=lambda: [80.0] * 4 + [20.0] * 3)
