"""Differential inverse kinematics: workpiece twist (user frame) -> Gen3 joint velocities.

`TwistToJointVelocity` is a discrete LeafSystem running at the scenario's
control period. Each period it solves Drake's `DoDifferentialInverseKinematics`
QP for the joint velocity that moves the workpiece centre with the commanded
linear velocity v and turns the workpiece about its centre with the commanded
angular velocity w (docs/interfaces.md (frames and the meaning of a twist); both given in the user frame U), subject to
joint position limits (with a margin), joint velocity and acceleration limits,
and a Cartesian speed limit, with joint centering in the null space. Then the
part of the answer that would drive the arm, gripper or part into the cell
(table, mold, glass) is removed: a robot-cell pair may close in no faster than
its distance beyond `min_cell_clearance_m` allows (`rtcohand_drake.cell.clearance`).

Input ports
  twist_command           (6) [vx vy vz wx wy wz], m/s and rad/s, user frame
  gen3.position_measured  (7) rad

Output ports
  gen3.velocity_command   (7) rad/s
  follow_status           (2) [status, ratio]: status 0 = following, 1 = slowed by a
                          limit (ratio < follow_ratio_threshold), 2 = stuck, 3 = no
                          solution (the command is then zero), 4 = invalid
                          (non-finite) twist, treated as zero, 5 = held back from
                          the cell (clearance); ratio = the fraction of the
                          commanded twist that the joint velocities achieve.

A zero twist means no motion at all: joint centering is switched off, so the
arm never drifts in its null space when nobody asks it to move.
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc
import enum
import math

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsParameters,
    DifferentialInverseKinematicsStatus,
    DoDifferentialInverseKinematics,
)
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from rtcohand_drake.cell.clearance import CellClearance, hold_clearance
from rtcohand_drake.cell.layout import Cell
from rtcohand_drake.cell.plant import make_control_plant
from rtcohand_drake.interfaces import FOLLOW_STATUS, POSITION_MEASURED, TWIST_COMMAND, VELOCITY_COMMAND


@dc.dataclass
class DiffIk:
    """Differential inverse kinematics limits and gains."""

    # Fraction of the actuators' speed limits (80 deg/s large, 70 deg/s small) the solver may use.
    joint_velocity_fraction: float = 0.5
    joint_acceleration_rad_s2: float = 4.0
    # Keep this far inside the limited joints' position limits (MoveIt Servo's default margin).
    joint_position_margin_rad: float = 0.1
    # Continuous joints have no limit; the solver uses +-this to stay finite.
    continuous_joint_range_rad: float = 4 * math.pi
    # Cartesian speed limits on the workpiece centre (ISO 10218 reduced speed: 0.25 m/s).
    max_linear_speed_m_s: float = 0.25
    max_angular_speed_rad_s: float = 1.0
    joint_centering_gain: float = 0.5
    # Below this ratio of achieved to commanded twist the controller reports that it cannot follow.
    follow_ratio_threshold: float = 0.9
    # Clearance from the cell (table, mold, glass) for the arm, gripper and part: a pair
    # closer than cell_clearance_within_m may shrink at most at (d - margin) / approach time,
    # and not at all inside min_cell_clearance_m (rtcohand_drake.cell.clearance). 0 switches it off.
    min_cell_clearance_m: float = 0.02
    cell_clearance_within_m: float = 0.10
    clearance_approach_time_s: float = 0.2


class FollowStatus(enum.IntEnum):
    FOLLOWING = 0
    SLOWED = 1
    STUCK = 2
    NO_SOLUTION = 3
    INVALID_INPUT = 4
    CLEARANCE = 5


def clamp_twist(twist: np.ndarray, max_linear: float, max_angular: float) -> np.ndarray:
    """Scales v and w separately so |v| <= max_linear and |w| <= max_angular (direction kept)."""
    twist = np.array(twist, dtype=float)
    for part, limit in ((slice(0, 3), max_linear), (slice(3, 6), max_angular)):
        norm = np.linalg.norm(twist[part])
        if norm > limit:
            twist[part] *= limit / norm
    return twist


class TwistToJointVelocity(LeafSystem):
    """Commanded workpiece twist -> joint velocity command, by differential IK (see module doc)."""

    def __init__(self, config: "DiffIk", cell: Cell, q_nominal_rad, control_period_s: float):
        """`config`: the scenario's `diff_ik`; `cell`: its layout; `q_nominal_rad`: the
        posture the joint centering pulls toward (the scenario's `robot.q0_rad`)."""
        super().__init__()
        self._plant, instances = make_control_plant(cell)
        self._plant_context = self._plant.CreateDefaultContext()
        self._frame_E = self._plant.GetFrameByName("workpiece", instances["workpiece"])
        self._R_WU = cell.user_frame.to_rigid_transform().rotation()
        cfg = config
        self._cfg = cfg
        self._dt = control_period_s
        n = self._plant.num_velocities()
        assert n == 7, "the control plant must have exactly the arm's 7 degrees of freedom"

        params = DifferentialInverseKinematicsParameters(num_positions=n, num_velocities=n)
        params.set_time_step(self._dt)
        lower = self._plant.GetPositionLowerLimits().copy()
        upper = self._plant.GetPositionUpperLimits().copy()
        continuous = ~np.isfinite(lower) | ~np.isfinite(upper)
        lower = np.where(continuous, -cfg.continuous_joint_range_rad, lower + cfg.joint_position_margin_rad)
        upper = np.where(continuous, cfg.continuous_joint_range_rad, upper - cfg.joint_position_margin_rad)
        params.set_joint_position_limits((lower, upper))
        self.joint_position_limits = (lower, upper)
        v_max = cfg.joint_velocity_fraction * self._plant.GetVelocityUpperLimits()
        params.set_joint_velocity_limits((-v_max, v_max))
        self.joint_velocity_limit = v_max
        a = np.full(n, cfg.joint_acceleration_rad_s2)
        params.set_joint_acceleration_limits((-a, a))
        params.set_end_effector_angular_speed_limit(cfg.max_angular_speed_rad_s)
        lin = np.full(3, cfg.max_linear_speed_m_s)
        params.set_end_effector_translational_velocity_limits(-lin, lin)
        params.set_nominal_joint_position(np.asarray(q_nominal_rad, float))
        self._params = params
        self._clearance = CellClearance(cell) if cfg.min_cell_clearance_m > 0 else None
        self._centering = cfg.joint_centering_gain * np.eye(n)
        self._no_centering = np.zeros((n, n))

        self._twist = self.DeclareVectorInputPort(TWIST_COMMAND, 6)
        self._q = self.DeclareVectorInputPort(POSITION_MEASURED, n)
        self._v_state = self.DeclareDiscreteState(n)
        self._status_state = self.DeclareDiscreteState(np.array([0.0, 1.0]))
        self.DeclarePeriodicDiscreteUpdateEvent(self._dt, 0.0, self._update)
        self.DeclareStateOutputPort(VELOCITY_COMMAND, self._v_state)
        self.DeclareStateOutputPort(FOLLOW_STATUS, self._status_state)

    @property
    def control_plant(self):
        return self._plant

    def desired_spatial_velocity(self, twist_U: np.ndarray) -> np.ndarray:
        """[w_W; v_W] (Drake's spatial-velocity order) for a user-frame twist [v_U; w_U]."""
        R = self._R_WU.matrix()
        return np.concatenate([R @ twist_U[3:6], R @ twist_U[0:3]])

    def solve(self, q: np.ndarray, v_current: np.ndarray, twist_U: np.ndarray) -> tuple[np.ndarray, FollowStatus, float]:
        """One differential-IK step; returns (v_next, status, achieved ratio)."""
        if not np.all(np.isfinite(twist_U)) or not np.all(np.isfinite(q)):
            twist_U = np.zeros(6)
            invalid = True
        else:
            invalid = False
        twist_U = clamp_twist(twist_U, self._cfg.max_linear_speed_m_s, self._cfg.max_angular_speed_rad_s)
        if not twist_U.any() and not np.any(v_current):
            # At rest and asked for no motion: the QP's answer is zero; skip it.
            return np.zeros_like(v_current), FollowStatus.INVALID_INPUT if invalid else FollowStatus.FOLLOWING, 1.0
        self._plant.SetPositions(self._plant_context, q)
        J = self._plant.CalcJacobianSpatialVelocity(
            self._plant_context, JacobianWrtVariable.kV, self._frame_E, np.zeros(3),
            self._plant.world_frame(), self._plant.world_frame())
        V = self.desired_spatial_velocity(twist_U)
        moving = np.linalg.norm(V) > 1e-9
        self._params.set_joint_centering_gain(self._centering if moving else self._no_centering)
        # A joint that the servo's lag carried past a (margin-shrunk) limit may not go
        # further, but is not forced back at once: that would make the QP infeasible.
        lower, upper = self.joint_position_limits
        self._params.set_joint_position_limits((np.minimum(lower, q), np.maximum(upper, q)))
        result = DoDifferentialInverseKinematics(q, v_current, V, J, self._params)
        dv = self._cfg.joint_acceleration_rad_s2 * self._dt
        if result.status == DifferentialInverseKinematicsStatus.kNoSolutionFound or result.joint_velocities is None:
            # Stop at the acceleration limit rather than at once (never into the cell).
            v_next, _ = self.keep_clear(q, v_current - np.clip(v_current, -dv, dv))
            return v_next, FollowStatus.NO_SOLUTION, 0.0
        v_next = np.asarray(result.joint_velocities).reshape(-1)
        # The QP solver meets its bounds to a tolerance; the limits are hard, so clip.
        v_next = np.clip(v_next, v_current - dv, v_current + dv)
        v_next, held = self.keep_clear(q, v_next)
        v_next = np.clip(v_next, -self.joint_velocity_limit, self.joint_velocity_limit)
        if not moving:
            ratio = 1.0
        else:
            ratio = float(np.dot(J @ v_next, V) / np.dot(V, V))
        if invalid:
            status = FollowStatus.INVALID_INPUT
        elif held:
            status = FollowStatus.CLEARANCE
        elif result.status == DifferentialInverseKinematicsStatus.kStuck:
            status = FollowStatus.STUCK
        elif ratio < self._cfg.follow_ratio_threshold:
            status = FollowStatus.SLOWED
        else:
            status = FollowStatus.FOLLOWING
        return v_next, status, ratio

    def keep_clear(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, bool]:
        """v with what would drive the robot into the cell removed; (v, whether anything was)."""
        if self._clearance is None:
            return v, False
        cfg = self._cfg
        pairs = self._clearance.close_pairs(q, cfg.cell_clearance_within_m)
        return hold_clearance(v, pairs, cfg.min_cell_clearance_m, cfg.clearance_approach_time_s)

    def _update(self, context, discrete_state):
        q = self._q.Eval(context)
        v_current = context.get_discrete_state(self._v_state).get_value()
        v_next, status, ratio = self.solve(q, v_current, self._twist.Eval(context))
        discrete_state.set_value(self._v_state, v_next)
        discrete_state.set_value(self._status_state, np.array([float(status), ratio]))

    def workpiece_pose(self, q: np.ndarray) -> RigidTransform:
        """X_WE of the workpiece centre at joint angles q (control plant kinematics)."""
        self._plant.SetPositions(self._plant_context, q)
        return self._frame_E.CalcPoseInWorld(self._plant_context)
