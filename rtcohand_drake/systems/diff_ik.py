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
import contextlib
import dataclasses as dc
import enum
import functools
import math
import os
import sys

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
    # Which QP answers each period: "drake_system" (Drake's DifferentialInverseKinematicsSystem,
    # built from its ingredients) or "legacy" (DoDifferentialInverseKinematics plus the
    # clearance projection). See SOLVERS.
    solver: str = "legacy"
    # drake_system only. Weight of the twist-tracking least-squares cost against the joint
    # centering cost (Drake advises about 100).
    tracking_weight: float = 100.0
    # drake_system only. A joint's speed toward its limit is cut linearly from this distance
    # to the limit down to zero at joint_position_margin_rad (Drake's JointVelocityLimitConstraint).
    joint_position_influence_rad: float = 0.3


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


class _TwistController(LeafSystem):
    """The ports, state, limits and status shared by the solvers (see module doc).

    A solver implements `_solve_moving(q, v_current, V, J, moving)` -> (v_next or
    None when its QP has no solution, stuck, held back from the cell)."""

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
        self._q_nominal = np.asarray(q_nominal_rad, float)
        n = self._plant.num_velocities()
        assert n == 7, "the control plant must have exactly the arm's 7 degrees of freedom"
        lower = self._plant.GetPositionLowerLimits().copy()
        upper = self._plant.GetPositionUpperLimits().copy()
        self._continuous = ~np.isfinite(lower) | ~np.isfinite(upper)
        self.plant_position_limits = (np.where(self._continuous, -cfg.continuous_joint_range_rad, lower),
                                      np.where(self._continuous, cfg.continuous_joint_range_rad, upper))
        lower = np.where(self._continuous, -cfg.continuous_joint_range_rad, lower + cfg.joint_position_margin_rad)
        upper = np.where(self._continuous, cfg.continuous_joint_range_rad, upper - cfg.joint_position_margin_rad)
        self.joint_position_limits = (lower, upper)
        self.joint_velocity_limit = cfg.joint_velocity_fraction * self._plant.GetVelocityUpperLimits()

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
        v_next, stuck, held = self._solve_moving(q, v_current, V, J, moving)
        dv = self._cfg.joint_acceleration_rad_s2 * self._dt
        if v_next is None:
            # Stop at the acceleration limit rather than at once (never into the cell).
            v_next, _ = self._keep_clear_after_failure(q, v_current - np.clip(v_current, -dv, dv))
            return v_next, FollowStatus.NO_SOLUTION, 0.0
        ratio = float(np.dot(J @ v_next, V) / np.dot(V, V)) if moving else 1.0
        if invalid:
            status = FollowStatus.INVALID_INPUT
        elif held:
            status = FollowStatus.CLEARANCE
        elif stuck:
            status = FollowStatus.STUCK
        elif ratio < self._cfg.follow_ratio_threshold:
            status = FollowStatus.SLOWED
        else:
            status = FollowStatus.FOLLOWING
        return v_next, status, ratio

    def _clip_to_limits(self, v_next: np.ndarray, v_current: np.ndarray) -> np.ndarray:
        """The QP solvers meet their bounds to a tolerance; the limits are hard, so clip."""
        dv = self._cfg.joint_acceleration_rad_s2 * self._dt
        v_next = np.clip(v_next, v_current - dv, v_current + dv)
        return np.clip(v_next, -self.joint_velocity_limit, self.joint_velocity_limit)

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


class TwistToJointVelocity(_TwistController):
    """Commanded workpiece twist -> joint velocity command, by `DoDifferentialInverseKinematics`
    and the clearance projection (solver "legacy"; see module doc)."""

    def __init__(self, config: "DiffIk", cell: Cell, q_nominal_rad, control_period_s: float):
        super().__init__(config, cell, q_nominal_rad, control_period_s)
        cfg, n = config, 7
        params = DifferentialInverseKinematicsParameters(num_positions=n, num_velocities=n)
        params.set_time_step(self._dt)
        params.set_joint_position_limits(self.joint_position_limits)
        params.set_joint_velocity_limits((-self.joint_velocity_limit, self.joint_velocity_limit))
        a = np.full(n, cfg.joint_acceleration_rad_s2)
        params.set_joint_acceleration_limits((-a, a))
        params.set_end_effector_angular_speed_limit(cfg.max_angular_speed_rad_s)
        lin = np.full(3, cfg.max_linear_speed_m_s)
        params.set_end_effector_translational_velocity_limits(-lin, lin)
        params.set_nominal_joint_position(self._q_nominal)
        self._params = params
        self._clearance = CellClearance(cell) if cfg.min_cell_clearance_m > 0 else None
        self._centering = cfg.joint_centering_gain * np.eye(n)
        self._no_centering = np.zeros((n, n))

    def _solve_moving(self, q, v_current, V, J, moving):
        self._params.set_joint_centering_gain(self._centering if moving else self._no_centering)
        # A joint that the servo's lag carried past a (margin-shrunk) limit may not go
        # further, but is not forced back at once: that would make the QP infeasible.
        lower, upper = self.joint_position_limits
        self._params.set_joint_position_limits((np.minimum(lower, q), np.maximum(upper, q)))
        result = DoDifferentialInverseKinematics(q, v_current, V, J, self._params)
        if result.status == DifferentialInverseKinematicsStatus.kNoSolutionFound or result.joint_velocities is None:
            return None, False, False
        v_next = self._clip_to_limits(np.asarray(result.joint_velocities).reshape(-1), v_current)
        v_next, held = self.keep_clear(q, v_next)
        v_next = np.clip(v_next, -self.joint_velocity_limit, self.joint_velocity_limit)
        return v_next, result.status == DifferentialInverseKinematicsStatus.kStuck, held

    def _keep_clear_after_failure(self, q, v):
        return self.keep_clear(q, v)

    def keep_clear(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, bool]:
        """v with what would drive the robot into the cell removed; (v, whether anything was)."""
        if self._clearance is None:
            return v, False
        cfg = self._cfg
        pairs = self._clearance.close_pairs(q, cfg.cell_clearance_within_m)
        return hold_clearance(v, pairs, cfg.min_cell_clearance_m, cfg.clearance_approach_time_s)


# Below this fraction of the commanded twist, with a solution, the arm counts as stuck
# (DoDifferentialInverseKinematics's own test on its speed scale).
STUCK_RATIO = 1e-2
# A collision row counts as binding within this rate of its bound (m/s).
ACTIVE_ROW_TOLERANCE_M_S = 1e-3
ROBOT_MODELS = ("gen3", "gripper", "workpiece")


@contextlib.contextmanager
def _console_silenced():
    """Standard output and error closed at the file-descriptor level for the block.

    Drake's system solves with OSQP and options of its own, and OSQP prints a line
    ("Polishing not needed ...") at most solves; a failed solve is logged as a warning.
    Both reach the console from C, every period; the failure is reported in
    `follow_status` instead."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        os.dup2(_devnull(), 1)
        os.dup2(_devnull(), 2)
        yield
    finally:
        _libc().fflush(None)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)


@functools.cache
def _devnull() -> int:
    return os.open(os.devnull, os.O_WRONLY)


@functools.cache
def _libc():
    import ctypes

    return ctypes.CDLL(None)


class TwistToJointVelocityDrakeSystem(_TwistController):
    """Commanded workpiece twist -> joint velocity command, by Drake's
    `DifferentialInverseKinematicsSystem` (solver "drake_system"; see module doc).

    The QP is Drake's, built from its ingredients: `LeastSquaresCost` on the
    workpiece's spatial velocity (world frame), `JointCenteringCost` toward
    `q_nominal_rad`, `CartesianVelocityLimitConstraint`,
    `JointVelocityLimitConstraint` (the speed limits intersected with what the
    acceleration limit allows this period; speed toward a position limit cut to
    zero at the margin) and `CollisionConstraint` against the table, mold and
    glass through a `SceneGraphCollisionChecker`. The inner system is evaluated
    inside this system's periodic update, on its own context.

    Clearance: the collision constraint's horizon is `clearance_approach_time_s`,
    so a pair closer than `cell_clearance_within_m` closes in at most at
    (d - min_cell_clearance_m) / approach time. A body pair already inside the
    margin is held where it is (the checker's padding for that pair is set to
    d - margin for the period) rather than pushed away, so the part seated in
    the mold can be lifted out.
    """

    def __init__(self, config: "DiffIk", cell: Cell, q_nominal_rad, control_period_s: float):
        from pydrake.common import Parallelism
        from pydrake.common.value import AbstractValue
        from pydrake.multibody.inverse_kinematics import DifferentialInverseKinematicsSystem as DiffIkSystem
        from pydrake.multibody.math import SpatialVelocity
        from pydrake.planning import DofMask, JointLimits, RobotDiagramBuilder, SceneGraphCollisionChecker
        from pydrake.systems.framework import BusValue

        from rtcohand_drake.cell.plant import add_cell_models

        super().__init__(config, cell, q_nominal_rad, control_period_s)
        cfg, n = config, 7
        self._AbstractValue, self._SpatialVelocity, self._BusValue = AbstractValue, SpatialVelocity, BusValue
        self._JointLimits = JointLimits
        robot_builder = RobotDiagramBuilder(time_step=0.0)
        plant = robot_builder.plant()
        instances = add_cell_models(plant, cell)
        plant.Finalize()
        robot = [instances[name] for name in ROBOT_MODELS]
        self._checker = SceneGraphCollisionChecker(
            model=robot_builder.Build(), robot_model_instances=robot, edge_step_size=0.05,
            env_collision_padding=0.0, self_collision_padding=0.0, implicit_context_parallelism=Parallelism(False))
        bodies = [plant.get_body(i) for r in robot for i in plant.GetBodyIndices(r)]
        # Self-collision is left to the joint limits (as in the station): only robot-cell pairs count.
        for k, a in enumerate(bodies):
            for b in bodies[k + 1:]:
                self._checker.SetCollisionFilteredBetween(a, b, True)
        self._checker_plant = plant
        self._padded: set = set()
        self._frame_name = self._frame_E.scoped_name().to_string()

        lower, upper = self.plant_position_limits
        self._velocity_limits = JointLimits(lower, upper, -self.joint_velocity_limit, self.joint_velocity_limit,
                                            np.full(n, -np.inf), np.full(n, np.inf))
        self._joint_velocity = DiffIkSystem.JointVelocityLimitConstraint(
            DiffIkSystem.JointVelocityLimitConstraint.Config(
                min_margin=cfg.joint_position_margin_rad, influence_margin=cfg.joint_position_influence_rad),
            self._velocity_limits)
        V_limit = np.concatenate([np.full(3, cfg.max_angular_speed_rad_s), np.full(3, cfg.max_linear_speed_m_s)])
        recipe = DiffIkSystem.Recipe()
        recipe.AddIngredient(DiffIkSystem.LeastSquaresCost(
            DiffIkSystem.LeastSquaresCost.Config(cartesian_qp_weight=cfg.tracking_weight)))
        recipe.AddIngredient(DiffIkSystem.JointCenteringCost(
            DiffIkSystem.JointCenteringCost.Config(posture_gain=cfg.joint_centering_gain)))
        recipe.AddIngredient(DiffIkSystem.CartesianVelocityLimitConstraint(
            DiffIkSystem.CartesianVelocityLimitConstraint.Config(V_next_TG_limit=V_limit)))
        recipe.AddIngredient(self._joint_velocity)
        self._clearance_on = cfg.min_cell_clearance_m > 0
        if self._clearance_on:
            recipe.AddIngredient(DiffIkSystem.CollisionConstraint(DiffIkSystem.CollisionConstraint.Config(
                safety_distance=cfg.min_cell_clearance_m, influence_distance=cfg.cell_clearance_within_m)))
        self._system = DiffIkSystem(
            recipe=recipe, task_frame="world", collision_checker=self._checker, active_dof=DofMask(n, True),
            time_step=cfg.clearance_approach_time_s, K_VX=1.0, Vd_TG_limit=SpatialVelocity(V_limit))
        self._system_context = self._system.CreateDefaultContext()

    @property
    def drake_system(self):
        """The inner `DifferentialInverseKinematicsSystem`."""
        return self._system

    def _hold_pairs_inside_margin(self, q):
        """Pads each robot-cell body pair already inside the margin up to it (held, not pushed);
        returns the checker's clearance (unpadded distances)."""
        cfg = self._cfg
        for a, b in self._padded:
            self._checker.SetPaddingBetween(a, b, 0.0)
        self._padded = set()
        clearance = self._checker.CalcRobotClearance(q, cfg.cell_clearance_within_m)
        closest: dict = {}
        for i, j, d in zip(clearance.robot_indices(), clearance.other_indices(), clearance.distances()):
            closest[(i, j)] = min(d, closest.get((i, j), np.inf))
        for (i, j), d in closest.items():
            if d < cfg.min_cell_clearance_m:
                a, b = self._checker_plant.get_body(i), self._checker_plant.get_body(j)
                self._checker.SetPaddingBetween(a, b, d - cfg.min_cell_clearance_m)
                self._padded.add((a, b))
        return clearance

    def _solve_moving(self, q, v_current, V, J, moving):
        cfg, system, context = self._cfg, self._system, self._system_context
        dv = cfg.joint_acceleration_rad_s2 * self._dt
        lim = self._velocity_limits
        v_lo = np.maximum(-self.joint_velocity_limit, v_current - dv)
        v_hi = np.minimum(self.joint_velocity_limit, v_current + dv)
        self._joint_velocity.SetJointLimits(self._JointLimits(
            lim.position_lower(), lim.position_upper(), v_lo, v_hi, lim.acceleration_lower(), lim.acceleration_upper()))
        clearance = self._hold_pairs_inside_margin(q) if self._clearance_on else None
        system.get_input_port_position().FixValue(context, q)
        # No centering when no motion is asked for: the arm never drifts in its null space.
        system.get_input_port_nominal_posture().FixValue(context, self._q_nominal if moving else q)
        bus = self._BusValue()
        bus.Set(self._frame_name, self._AbstractValue.Make(self._SpatialVelocity(V[:3], V[3:])))
        system.get_input_port_desired_cartesian_velocities().FixValue(context, bus)
        with _console_silenced():
            v_qp = system.get_output_port_commanded_velocity().Eval(context).copy()
        if moving and not v_qp.any():
            return None, False, False  # Drake's system answers exactly zero when its QP fails
        v_next = self._clip_to_limits(v_qp, v_current)
        held = False
        if clearance is not None:
            rates = clearance.jacobians() @ v_next
            bounds = -np.maximum(clearance.distances() - cfg.min_cell_clearance_m, 0.0) / cfg.clearance_approach_time_s
            held = bool(np.any((rates < 0) & (rates <= bounds + ACTIVE_ROW_TOLERANCE_M_S)))
        ratio = float(np.dot(J @ v_next, V) / np.dot(V, V)) if moving else 1.0
        return v_next, moving and ratio < STUCK_RATIO, held

    def _keep_clear_after_failure(self, q, v):
        # Decelerating along the current motion; the collision constraint's horizon leaves
        # room for the stopping distance at the acceleration limit.
        return v, False


# The controllers by `diff_ik.solver`; each has the ports in the module doc.
SOLVERS = {"drake_system": TwistToJointVelocityDrakeSystem, "legacy": TwistToJointVelocity}


def make_twist_to_joint_velocity(scenario) -> _TwistController:
    """The scenario's differential-IK controller (`scenario.diff_ik.solver`)."""
    cls = SOLVERS[scenario.diff_ik.solver]
    return cls(scenario.diff_ik, scenario.cell, scenario.robot.q0_rad, scenario.control_period_s)
