"""Differential inverse kinematics: workpiece twist (user frame) -> Gen3 joint velocities.

`TwistToJointVelocity` is a discrete LeafSystem running at the scenario's
control period. Each period it evaluates Drake's own
`DifferentialInverseKinematicsSystem` (pydrake.multibody.inverse_kinematics),
a QP built from Drake's ingredients, for the joint velocity that moves the
workpiece centre with the commanded linear velocity v and turns the workpiece
about its centre with the commanded angular velocity w (docs/interfaces.md
(frames and the meaning of a twist); both given in the user frame U):

- `LeastSquaresCost`: |V_desired - J v|², V in the world frame, weight `tracking_weight`,
  and a second one on the linear half alone (axis mask [0 0 0 1 1 1]), weight
  `linear_tracking_weight`, so the part turns about its centre instead of swinging it aside;
- `JointCenteringCost`: toward the nominal posture (the scenario's `robot.q0_rad`)
  in the null space of J, gain `joint_centering_gain`;
- `CartesianVelocityLimitConstraint`: each component of the workpiece's angular
  and linear velocity within `max_angular_speed_rad_s` and `max_linear_speed_m_s`;
- `JointVelocityLimitConstraint`: the joint speed limits intersected with what
  the acceleration limit allows from the current command this period; a joint's
  speed toward its position limit is cut linearly from
  `joint_position_influence_rad` to zero at `joint_position_margin_rad`;
- `CollisionConstraint` through a `SceneGraphCollisionChecker` (the arm, gripper
  and part against the table, mold and glass): with the constraint's horizon
  set to `clearance_approach_time_s`, a pair closer than `cell_clearance_within_m`
  may close in at most at (d - min_cell_clearance_m) / approach time. A pair
  already inside the margin (the part seated in the mold) is held where it is,
  never pushed away: its padding in the checker is set to d - margin for the period.

The answer is clipped to the acceleration and speed limits (the QP solver meets
its bounds to a tolerance; the limits are hard). Then, since the least-squares
cost may trade one component of the twist for another (a turn asked for, the
part's centre swung aside at speed when a joint limit binds), the command is
scaled down until the achieved motion beyond the commanded one is within
`max_unrequested_linear_m_s` and `max_unrequested_angular_rad_s`
(`unrequested_scale`), and the part's speed (the norm of J v) within
`speed_cap_fraction` of `max_linear_speed_m_s` and `max_angular_speed_rad_s`
(the arm's position servo catches up after a lag, so the measured speed
overshoots what J v says by up to about 12 %): a slower command, so
every limit above still holds.

Input ports
  twist_command           (6) [vx vy vz wx wy wz], m/s and rad/s, user frame
  gen3.position_measured  (7) rad

Output ports
  gen3.velocity_command   (7) rad/s
  follow_status           (2) [status, ratio]: status 0 = following, 1 = slowed by a
                          limit (ratio < follow_ratio_threshold), 2 = stuck (a solution,
                          but under 1 % of the commanded twist), 3 = no solution (the
                          command then comes down at the acceleration limit), 4 = invalid
                          (non-finite) twist, treated as zero, 5 = held back from
                          the cell (a collision row binding); ratio = the fraction of the
                          commanded twist that the joint velocities achieve.

A zero twist means no motion at all: the nominal posture is then the current
one, so the arm never drifts in its null space when nobody asks it to move.
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import contextlib
import dataclasses as dc
import enum
import functools
import math
import os
import sys
import threading

import numpy as np
from pydrake.common import Parallelism
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import DifferentialInverseKinematicsSystem as DiffIkSystem
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.planning import DofMask, JointLimits, RobotDiagramBuilder, SceneGraphCollisionChecker
from pydrake.systems.framework import BusValue, LeafSystem

from rtcohand_drake.cell.geometry import vector_norm
from rtcohand_drake.cell.layout import Cell
from rtcohand_drake.cell.plant import add_cell_models, make_control_plant
from rtcohand_drake.interfaces import FOLLOW_STATUS, POSITION_MEASURED, TWIST_COMMAND, TWIST_DIM, VELOCITY_COMMAND


@dc.dataclass
class DiffIk:
    """Differential inverse kinematics limits and gains."""

    # Fraction of the actuators' speed limits (80 deg/s large, 70 deg/s small) the solver may use.
    joint_velocity_fraction: float = 0.5
    joint_acceleration_rad_s2: float = 4.0
    # Speed toward a limited joint's position limit is zero this far inside it (MoveIt Servo's
    # default margin) ...
    joint_position_margin_rad: float = 0.1
    # ... and cut linearly from this distance on (Drake's JointVelocityLimitConstraint).
    joint_position_influence_rad: float = 0.3
    # Continuous joints have no limit; the solver uses +-this to stay finite.
    continuous_joint_range_rad: float = 4 * math.pi
    # Cartesian speed limits on the workpiece centre (ISO 10218 reduced speed: 0.25 m/s).
    max_linear_speed_m_s: float = 0.25
    max_angular_speed_rad_s: float = 1.0
    # Weight of the twist-tracking least-squares cost; the joint centering cost has weight 1
    # (Drake advises about 100 between them).
    tracking_weight: float = 100.0
    # Weight of a second least-squares cost on the linear half of the twist alone (Drake's
    # LeastSquaresCost with the axis mask [0 0 0 1 1 1]): the first cost alone weighs an error of
    # 0.1 m/s like one of 0.1 rad/s, so a turn was tracked by swinging the part's centre aside (up
    # to 0.2 m/s). 24 x tracking_weight weighs 1 cm/s of the centre like 0.05 rad/s of turn. Chosen
    # on development runs: 10,000 (100 x) left the QP trading the turn away instead (docs/archive.md,
    # "The linear tracking weight"). 0: none.
    linear_tracking_weight: float = 2400.0
    joint_centering_gain: float = 0.5
    # Below this ratio of achieved to commanded twist the controller reports that it cannot follow.
    follow_ratio_threshold: float = 0.9
    # Motion nobody asked for: in each half of the achieved twist, what is not along that half's
    # command or goes beyond it (`unrequested_motion`; the least-squares cost trades one component
    # for another when a joint limit binds, and the part's centre can then swing at full speed
    # while only a turn was asked for). The joint command is scaled down until it is within these
    # bounds. 0 switches that half off.
    max_unrequested_linear_m_s: float = 0.05
    max_unrequested_angular_rad_s: float = 0.3
    # The part's speed (the norm of J v) is capped at this fraction of the speed limits: the arm's
    # position servo lags its target and then catches up, so the part's measured speed overshoots
    # J v by up to 12 % when a motion starts (at 0.95 a 0.25 m/s command still measured 0.263 m/s
    # in free space; at 0.9, at most 0.251 m/s).
    speed_cap_fraction: float = 0.9
    # Clearance from the cell (table, mold, glass) for the arm, gripper and part: a pair
    # closer than cell_clearance_within_m may shrink at most at (d - margin) / approach time,
    # and not at all inside min_cell_clearance_m. 0 switches it off.
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


# With a solution, below this fraction of the commanded twist the arm counts as stuck
# (the threshold DoDifferentialInverseKinematics puts on its speed scale).
STUCK_RATIO = 1e-2
# A collision row counts as binding within this rate of its bound (m/s).
BINDING_ROW_TOLERANCE_M_S = 1e-3
ROBOT_MODELS = ("gen3", "gripper", "workpiece")
# The checker requires an edge step (rad, the spacing of configurations checked along a path
# between two postures); the controller only asks for the clearance at one posture each
# period, never along a path, so the value does not change what the controller does.
CHECKER_EDGE_STEP_RAD = 0.05


def unrequested_motion(V_achieved: np.ndarray, V_desired: np.ndarray) -> tuple[float, float]:
    """The motion beyond the command: (linear m/s, angular rad/s) of spatial velocities [w; v].

    Each half on its own. What a half achieves along its command, up to the command itself,
    was asked for (any share of it: a turn slowed by a joint limit while the part still
    translates as asked is fine); the rest of that half (sideways, backwards or beyond the
    command; all of it when the half's command is zero) was not."""
    sizes = []
    for half in (slice(3, 6), slice(0, 3)):
        achieved, desired = V_achieved[half], V_desired[half]
        dd = float(np.dot(desired, desired))
        share = min(max(float(np.dot(achieved, desired)) / dd, 0.0), 1.0) if dd > 1e-18 else 0.0
        sizes.append(vector_norm(achieved - share * desired))
    return sizes[0], sizes[1]


def unrequested_scale(V_achieved: np.ndarray, V_desired: np.ndarray, max_linear: float, max_angular: float) -> float:
    """The factor (0..1] to scale a joint command by so that the motion it makes beyond the
    commanded one (`unrequested_motion`) stays within max_linear (m/s) and max_angular (rad/s).
    That motion scales with the joint command, so one factor brings both halves within bounds.
    A bound of 0 leaves that half unchecked."""
    scale = 1.0
    for size, bound in zip(unrequested_motion(V_achieved, V_desired), (max_linear, max_angular)):
        if bound > 0 and size > bound:
            scale = min(scale, bound / size)
    return scale


def clamp_twist(twist: np.ndarray, max_linear: float, max_angular: float) -> np.ndarray:
    """Scales v and w separately so |v| <= max_linear and |w| <= max_angular (direction kept)."""
    twist = np.array(twist, dtype=float)
    for part, limit in ((slice(0, 3), max_linear), (slice(3, 6), max_angular)):
        norm = vector_norm(twist[part])
        if norm > limit:
            twist[part] *= limit / norm
    return twist


@contextlib.contextmanager
def _console_silenced():
    """Standard output and error closed at the file-descriptor level for the block.

    Drake's system solves with OSQP under options of its own, and OSQP prints a line
    ("Polishing not needed ...") at most solves; a failed solve is logged as a
    warning. Both reach the console from C every period; `follow_status` reports
    the failure instead. The descriptors are the process's, so controllers solving in
    several threads take turns (`_CONSOLE_LOCK`): otherwise one thread could save the
    other's /dev/null as "the console" and restore it, and the process would print
    nothing more."""
    with _CONSOLE_LOCK:
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


_CONSOLE_LOCK = threading.Lock()


@functools.cache
def _devnull() -> int:
    return os.open(os.devnull, os.O_WRONLY)


@functools.cache
def _libc():
    import ctypes

    return ctypes.CDLL(None)


def make_collision_checker(cell: Cell) -> tuple[SceneGraphCollisionChecker, object]:
    """A checker of the arm, gripper and held part (the robot) against the cell; (checker, its plant).

    Self-collision is left to the joint limits, as in the station: only robot-cell pairs count."""
    builder = RobotDiagramBuilder(time_step=0.0)
    plant = builder.plant()
    instances = add_cell_models(plant, cell)
    plant.Finalize()
    robot = [instances[name] for name in ROBOT_MODELS]
    checker = SceneGraphCollisionChecker(
        model=builder.Build(), robot_model_instances=robot, edge_step_size=CHECKER_EDGE_STEP_RAD,
        env_collision_padding=0.0, self_collision_padding=0.0, implicit_context_parallelism=Parallelism(False))
    bodies = [plant.get_body(i) for r in robot for i in plant.GetBodyIndices(r)]
    for k, a in enumerate(bodies):
        for b in bodies[k + 1:]:
            checker.SetCollisionFilteredBetween(a, b, True)
    return checker, plant


class TwistToJointVelocity(LeafSystem):
    """Commanded workpiece twist -> joint velocity command, by Drake's
    `DifferentialInverseKinematicsSystem` (see module doc). The inner system is
    evaluated inside this system's periodic update, on a context of its own."""

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
        self._dv = cfg.joint_acceleration_rad_s2 * control_period_s  # the most a joint's speed changes a period
        self._q_nominal = np.asarray(q_nominal_rad, float)
        n = self._plant.num_velocities()
        assert n == 7, "the control plant must have exactly the arm's 7 degrees of freedom"

        lower = self._plant.GetPositionLowerLimits().copy()
        upper = self._plant.GetPositionUpperLimits().copy()
        continuous = ~np.isfinite(lower) | ~np.isfinite(upper)
        lower = np.where(continuous, -cfg.continuous_joint_range_rad, lower)
        upper = np.where(continuous, cfg.continuous_joint_range_rad, upper)
        margin = np.where(continuous, 0.0, cfg.joint_position_margin_rad)
        # Where a joint stops: the limits shrunk by the margin.
        self.joint_position_limits = (lower + margin, upper - margin)
        self.joint_velocity_limit = cfg.joint_velocity_fraction * self._plant.GetVelocityUpperLimits()
        self._position_limits = (lower, upper)
        self._no_acceleration_limits = (np.full(n, -np.inf), np.full(n, np.inf))

        self._checker, self._checker_plant = make_collision_checker(cell)
        self._padded: list = []
        self._frame_name = self._frame_E.scoped_name().to_string()
        self._joint_velocity = DiffIkSystem.JointVelocityLimitConstraint(
            DiffIkSystem.JointVelocityLimitConstraint.Config(
                min_margin=cfg.joint_position_margin_rad, influence_margin=cfg.joint_position_influence_rad),
            self._joint_limits(-self.joint_velocity_limit, self.joint_velocity_limit))
        V_limit = np.concatenate([np.full(3, cfg.max_angular_speed_rad_s), np.full(3, cfg.max_linear_speed_m_s)])
        recipe = DiffIkSystem.Recipe()
        recipe.AddIngredient(DiffIkSystem.LeastSquaresCost(
            DiffIkSystem.LeastSquaresCost.Config(cartesian_qp_weight=cfg.tracking_weight)))
        if cfg.linear_tracking_weight > 0:
            recipe.AddIngredient(DiffIkSystem.LeastSquaresCost(DiffIkSystem.LeastSquaresCost.Config(
                cartesian_qp_weight=cfg.linear_tracking_weight,
                cartesian_axis_masks={self._frame_name: np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])})))
        recipe.AddIngredient(DiffIkSystem.JointCenteringCost(
            DiffIkSystem.JointCenteringCost.Config(posture_gain=cfg.joint_centering_gain)))
        recipe.AddIngredient(DiffIkSystem.CartesianVelocityLimitConstraint(
            DiffIkSystem.CartesianVelocityLimitConstraint.Config(V_next_TG_limit=V_limit)))
        recipe.AddIngredient(self._joint_velocity)
        self._clearance_on = cfg.min_cell_clearance_m > 0
        if self._clearance_on:
            recipe.AddIngredient(DiffIkSystem.CollisionConstraint(DiffIkSystem.CollisionConstraint.Config(
                safety_distance=cfg.min_cell_clearance_m, influence_distance=cfg.cell_clearance_within_m)))
        # The time step is the horizon over which the collision constraint lets a gap close
        # (the commands themselves go out every control period).
        self._system = DiffIkSystem(
            recipe=recipe, task_frame="world", collision_checker=self._checker, active_dof=DofMask(n, True),
            time_step=cfg.clearance_approach_time_s, K_VX=1.0, Vd_TG_limit=SpatialVelocity(V_limit))
        self._system_context = self._system.CreateDefaultContext()

        self._twist = self.DeclareVectorInputPort(TWIST_COMMAND, TWIST_DIM)
        self._q = self.DeclareVectorInputPort(POSITION_MEASURED, n)
        self._v_state = self.DeclareDiscreteState(n)
        self._status_state = self.DeclareDiscreteState(np.array([0.0, 1.0]))
        self.DeclarePeriodicDiscreteUpdateEvent(self._dt, 0.0, self._update)
        self.DeclareStateOutputPort(VELOCITY_COMMAND, self._v_state)
        self.DeclareStateOutputPort(FOLLOW_STATUS, self._status_state)

    @property
    def control_plant(self):
        return self._plant

    @property
    def drake_system(self):
        """The inner `DifferentialInverseKinematicsSystem`."""
        return self._system

    def _joint_limits(self, v_lower: np.ndarray, v_upper: np.ndarray) -> JointLimits:
        return JointLimits(*self._position_limits, v_lower, v_upper, *self._no_acceleration_limits)

    def desired_spatial_velocity(self, twist_U: np.ndarray) -> np.ndarray:
        """[w_W; v_W] (Drake's spatial-velocity order) for a user-frame twist [v_U; w_U]."""
        R = self._R_WU.matrix()
        return np.concatenate([R @ twist_U[3:6], R @ twist_U[0:3]])

    def solve(self, q: np.ndarray, v_current: np.ndarray, twist_U: np.ndarray) -> tuple[np.ndarray, FollowStatus, float]:
        """One differential-IK step; returns (v_next, status, achieved ratio).

        A non-finite twist is no command. With non-finite joint angles (a corrupt measurement)
        nothing about the arm is known: the joints come down at the acceleration limit and
        the plant is never given those angles."""
        if not np.isfinite(q).all():
            return self._come_down(v_current), FollowStatus.INVALID_INPUT, 0.0
        if not np.isfinite(twist_U).all():
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
        moving = vector_norm(V) > 1e-9
        cfg, dv = self._cfg, self._dv
        v_qp, clearance = self._solve_qp(q, v_current, V, moving)
        if v_qp is None:
            # Come down at the acceleration limit rather than at once. Every gap to the cell
            # was closing at most at (d - margin) / approach time, and the stop takes a
            # fraction of that time, so the arm stays clear of the margin.
            return self._come_down(v_current), FollowStatus.NO_SOLUTION, 0.0
        # np.minimum(np.maximum(...)) is np.clip's arithmetic, without its dispatch.
        v_next = np.minimum(np.maximum(v_qp, v_current - dv), v_current + dv)
        v_next = np.minimum(np.maximum(v_next, -self.joint_velocity_limit), self.joint_velocity_limit)
        # Bound the motion beyond the command, and the part's speed itself (the QP's limit is per
        # component, so its norm could reach sqrt(3) times the limit); a slower command is still
        # within every other limit. It comes down no faster than the acceleration limit allows.
        V_next = J @ v_next
        scale = unrequested_scale(V_next, V, cfg.max_unrequested_linear_m_s,
                                  cfg.max_unrequested_angular_rad_s) if moving else 1.0
        for part, limit in ((V_next[3:], cfg.max_linear_speed_m_s), (V_next[:3], cfg.max_angular_speed_rad_s)):
            speed, cap = vector_norm(part), cfg.speed_cap_fraction * limit
            if speed > cap:
                scale = min(scale, cap / speed)
        if scale < 1.0:
            v_next = np.minimum(np.maximum(scale * v_next, v_current - dv), v_current + dv)
            V_next = J @ v_next
        held = False
        if clearance is not None and clearance.size():
            rates = clearance.jacobians() @ v_next
            bounds = -np.maximum(clearance.distances() - cfg.min_cell_clearance_m, 0.0) / cfg.clearance_approach_time_s
            held = bool(np.any((rates < 0) & (rates <= bounds + BINDING_ROW_TOLERANCE_M_S)))
        ratio = float(np.dot(V_next, V) / np.dot(V, V)) if moving else 1.0
        if invalid:
            status = FollowStatus.INVALID_INPUT
        elif held:
            status = FollowStatus.CLEARANCE
        elif moving and ratio < STUCK_RATIO:
            status = FollowStatus.STUCK
        elif ratio < cfg.follow_ratio_threshold:
            status = FollowStatus.SLOWED
        else:
            status = FollowStatus.FOLLOWING
        return v_next, status, ratio

    def _come_down(self, v_current: np.ndarray) -> np.ndarray:
        """The joint speeds one period nearer rest at the acceleration limit (a non-finite speed
        counts as rest)."""
        v = np.where(np.isfinite(v_current), v_current, 0.0)
        return v - np.clip(v, -self._dv, self._dv)

    def _solve_qp(self, q, v_current, V, moving):
        """Drake's answer (None when its QP failed) and the clearance it was given (or None)."""
        self._joint_velocity.SetJointLimits(self._joint_limits(*self._velocity_bounds(q, v_current)))
        clearance = self._hold_pairs_inside_margin(q) if self._clearance_on else None
        system, context = self._system, self._system_context
        system.get_input_port_position().FixValue(context, q)
        system.get_input_port_nominal_posture().FixValue(context, self._q_nominal if moving else q)
        bus = BusValue()
        bus.Set(self._frame_name, AbstractValue.Make(SpatialVelocity(V[:3], V[3:])))
        system.get_input_port_desired_cartesian_velocities().FixValue(context, bus)
        try:
            with _console_silenced():
                v_qp = system.get_output_port_commanded_velocity().Eval(context).copy()
        except RuntimeError:
            return None, clearance  # limits the servo's lag made inconsistent: treated as no solution
        if moving and not v_qp.any():
            return None, clearance  # Drake's system answers exactly zero when its QP fails
        return v_qp, clearance

    def _velocity_bounds(self, q, v_current):
        """The bounds to give Drake's JointVelocityLimitConstraint so that, after it cuts the
        bound toward the nearer position limit by its factor s, the QP sees the speed limit
        (cut by s) intersected with what the acceleration limit allows this period.

        Joint by joint on Python floats (seven joints: numpy's dispatch would cost more than
        the arithmetic); the operations are those of the vector form."""
        cfg, dv = self._cfg, self._dv
        margin, influence = cfg.joint_position_margin_rad, cfg.joint_position_influence_rad
        lower, upper = self._position_limits
        lo_out, hi_out = [], []
        for qj, vj, v_max, low, up in zip(np.asarray(q, float).tolist(), np.asarray(v_current, float).tolist(),
                                          self.joint_velocity_limit.tolist(), lower.tolist(), upper.tolist()):
            lo, hi = max(-v_max, vj - dv), min(v_max, vj + dv)
            to_lower, to_upper = qj - low, up - qj
            near_upper = to_upper < to_lower  # the side Drake cuts (Drake's own test)
            s = min(max((min(to_lower, to_upper) - margin) / (influence - margin), 0.0), 1.0)
            # The cut bound, but never so tight that slowing down at the acceleration limit is
            # ruled out (a joint the servo's lag carried in too fast); the clip after the QP holds.
            if near_upper:
                hi = max(min(hi, v_max * s), lo + 1e-9)
            else:
                lo = min(max(lo, -v_max * s), hi - 1e-9)
            # A positive cut bound is passed divided by s, so that Drake's cut gives it back; a
            # bound of the other sign Drake only loosens toward 0 (the clip after the QP holds);
            # at s = 0 Drake's bound is 0, so the other bound must allow 0.
            if s > 0:
                if near_upper and hi > 0:
                    hi = hi / s
                elif not near_upper and lo < 0:
                    lo = lo / s
            elif near_upper:
                lo = min(lo, 0.0)
            else:
                hi = max(hi, 0.0)
            lo_out.append(lo)
            hi_out.append(hi)
        return np.array(lo_out), np.array(hi_out)

    def _hold_pairs_inside_margin(self, q):
        """Pads each robot-cell body pair already inside the margin up to it (held, not pushed);
        returns the checker's clearance without that padding."""
        cfg = self._cfg
        for a, b in self._padded:
            self._checker.SetPaddingBetween(a, b, 0.0)
        self._padded = []
        clearance = self._checker.CalcRobotClearance(q, cfg.cell_clearance_within_m)
        closest: dict = {}
        distances = clearance.distances()
        inside = np.flatnonzero(distances < cfg.min_cell_clearance_m)  # only these pairs can be padded
        if inside.size:
            robot, other = clearance.robot_indices(), clearance.other_indices()
            for k in inside:
                i, j, d = robot[k], other[k], distances[k]
                closest[(i, j)] = min(d, closest.get((i, j), np.inf))
        for (i, j), d in closest.items():
            if d < cfg.min_cell_clearance_m:
                a, b = self._checker_plant.get_body(i), self._checker_plant.get_body(j)
                self._checker.SetPaddingBetween(a, b, d - cfg.min_cell_clearance_m)
                self._padded.append((a, b))
        return clearance

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


def make_twist_to_joint_velocity(scenario) -> TwistToJointVelocity:
    """The scenario's differential-IK controller (every call site builds it here)."""
    return TwistToJointVelocity(scenario.diff_ik, scenario.cell, scenario.robot.q0_rad, scenario.control_period_s)
