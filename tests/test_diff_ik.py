"""Differential IK (Drake's DifferentialInverseKinematicsSystem): follows a commanded workpiece twist and respects every limit."""

import numpy as np
import pytest
from pydrake.math import RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from pydrake.multibody.inverse_kinematics import DifferentialInverseKinematicsSystem

from rtcohand_drake.systems.diff_ik import FollowStatus, clamp_twist, make_twist_to_joint_velocity, unrequested_scale
from rtcohand_drake.cell.initial_pose import GEN3_HOME_RAD
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.stations.sim import make_sim_station
from rtcohand_drake.interfaces import FOLLOW_STATUS, POSITION_MEASURED, TWIST_COMMAND, VELOCITY_COMMAND, WORKPIECE_POSE

# A posture with the workpiece in free space, well away from joint limits.
Q_FREE = GEN3_HOME_RAD + np.deg2rad([10, 10, 0, 15, 0, -10, 0])


@pytest.fixture(scope="module")
def scenario():
    s = load_scenario("inspection")
    s.robot.q0_rad = list(Q_FREE)
    return s


@pytest.fixture(scope="module")
def controller(scenario):
    return make_twist_to_joint_velocity(scenario)


def test_clamp_twist_keeps_direction():
    t = clamp_twist(np.array([0.3, 0.4, 0, 0, 0, 2.0]), 0.25, 1.0)
    assert np.linalg.norm(t[:3]) == pytest.approx(0.25)
    assert np.allclose(t[:3] / np.linalg.norm(t[:3]), [0.6, 0.8, 0])
    assert t[5] == pytest.approx(1.0)


def test_user_frame_mapping(controller, scenario):
    """A user-frame twist becomes [w_W; v_W] with R_WU from the scenario."""
    R_WU = RotationMatrix.MakeZRotation(np.pi)  # inspection.yaml: U is the world turned 180 deg about z
    twist = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    V = controller.desired_spatial_velocity(twist)
    assert np.allclose(V[3:], R_WU.multiply(twist[:3]))
    assert np.allclose(V[:3], R_WU.multiply(twist[3:]))


def _closed_loop(scenario, twist, duration):
    builder = DiagramBuilder()
    station = builder.AddSystem(make_sim_station(scenario))
    ik = builder.AddSystem(make_twist_to_joint_velocity(scenario))
    builder.Connect(station.GetOutputPort(POSITION_MEASURED), ik.GetInputPort(POSITION_MEASURED))
    builder.Connect(ik.GetOutputPort(VELOCITY_COMMAND), station.GetInputPort(VELOCITY_COMMAND))
    builder.ExportInput(ik.GetInputPort(TWIST_COMMAND), "twist")
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    diagram.GetInputPort("twist").FixValue(ctx, twist)
    samples = []
    dt = scenario.control_period_s
    for k in range(int(round(duration / dt))):
        t = (k + 0.5) * dt  # mid-period: exactly one controller update between samples
        sim.AdvanceTo(t)
        samples.append((t,
                        station.GetOutputPort(WORKPIECE_POSE).Eval(station.GetMyContextFromRoot(ctx)).copy(),
                        station.GetOutputPort(POSITION_MEASURED).Eval(station.GetMyContextFromRoot(ctx)).copy(),
                        ik.GetOutputPort(VELOCITY_COMMAND).Eval(ik.GetMyContextFromRoot(ctx)).copy(),
                        ik.GetOutputPort(FOLLOW_STATUS).Eval(ik.GetMyContextFromRoot(ctx)).copy()))
    return ik, samples


def _rotation(pose):
    from pydrake.common.eigen_geometry import Quaternion

    q = pose[3:7] / np.linalg.norm(pose[3:7])
    return RotationMatrix(Quaternion(q)).matrix()


@pytest.mark.parametrize("twist", [
    [0.05, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.04, -0.03, 0.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.15],
    [0.03, -0.02, 0.02, 0.1, -0.05, 0.08],
])
def test_follows_twist_in_free_space(scenario, twist):
    """Steady-state workpiece twist (user frame) within 5% of the command."""
    twist = np.array(twist)
    ik, samples = _closed_loop(scenario, twist, 1.5)
    (t0, p0, *_), (t1, p1, *_) = samples[-51], samples[-1]  # the last 0.5 s
    R_UW = RotationMatrix.MakeZRotation(np.pi).inverse().matrix()
    v_U = R_UW @ (p1[:3] - p0[:3]) / (t1 - t0)
    R_rel = _rotation(p1) @ _rotation(p0).T  # world-frame rotation over the window
    angle_axis = RotationMatrix(R_rel).ToAngleAxis()
    w_U = R_UW @ (angle_axis.axis() * angle_axis.angle()) / (t1 - t0)
    achieved = np.concatenate([v_U, w_U])
    error = np.linalg.norm(achieved - twist) / np.linalg.norm(twist)
    assert error < 0.05, (achieved, twist)
    assert all(s[4][0] == FollowStatus.FOLLOWING for s in samples[-50:])


def test_never_exceeds_limits_when_driven_into_them(scenario):
    """A long fast twist drives the arm to its limits; no limit is ever exceeded."""
    ik, samples = _closed_loop(scenario, np.array([0.0, 0.0, 0.0, 0.0, 0.0, 5.0]), 12.0)
    lower, upper = ik.joint_position_limits
    v_max = ik.joint_velocity_limit
    a_max = scenario.diff_ik.joint_acceleration_rad_s2
    v_prev = np.zeros(7)
    for _, pose, q, v, status in samples:
        assert np.all(np.abs(v) <= v_max + 1e-6)
        assert np.all(np.abs(v - v_prev) <= a_max * scenario.control_period_s + 1e-6)
        assert np.all(q >= lower - 0.02) and np.all(q <= upper + 0.02)
        v_prev = v
    # The angular command was clamped to the Cartesian limit, then to joint limits: it reports so.
    assert any(s[4][0] != FollowStatus.FOLLOWING for s in samples)


def test_unrequested_scale_bounds_the_motion_beyond_the_command():
    turn = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])  # [w; v]: a pure turn asked for
    assert unrequested_scale(0.7 * turn, turn, 0.05, 0.3) == 1.0  # slower, but only what was asked
    swung = np.array([0.0, 0.0, 1.0, 0.2, 0.1, 0.0])  # ... and the centre swung aside at 0.22 m/s
    scale = unrequested_scale(swung, turn, 0.05, 0.3)
    assert scale == pytest.approx(0.05 / np.hypot(0.2, 0.1))
    assert np.linalg.norm((scale * swung)[3:]) == pytest.approx(0.05)
    tilted = np.array([0.6, 0.0, 1.0, 0.0, 0.0, 0.0])  # a turn about another axis as well
    assert unrequested_scale(tilted, turn, 0.05, 0.3) == pytest.approx(0.5)
    assert unrequested_scale(tilted, turn, 0.05, 0.0) == 1.0  # 0: that half unchecked
    assert unrequested_scale(swung, np.zeros(6), 0.05, 0.3) < 0.3  # nothing asked: all of it is unrequested
    # Each half on its own: the translation as asked while the turn lags behind is all asked for ...
    both = np.array([0.0, 0.0, 0.8, 0.2, 0.0, 0.0])
    assert unrequested_scale(np.array([0.0, 0.0, 0.2, 0.2, 0.0, 0.0]), both, 0.05, 0.3) == 1.0
    # ... but backwards, or beyond the command, is not.
    assert unrequested_scale(np.array([0.0, 0.0, 0.0, -0.1, 0.0, 0.0]), both, 0.05, 0.3) == pytest.approx(0.5)
    assert unrequested_scale(np.array([0.0, 0.0, 0.0, 0.3, 0.0, 0.0]), both, 0.05, 0.3) == pytest.approx(0.5)


@pytest.mark.parametrize("twist", [[0.25, 0, 0, 0, 0, 0], [0, 0.25, 0, 0, 0, 0], [0, 0, 0.25, 0, 0, 0],
                                   [0, 0, -0.25, 0, 0, 0], [0.18, 0.18, 0, 0, 0, 0], [0, 0, 0, 0.7, 0.7, 0]])
def test_the_parts_measured_speed_stays_within_the_limits(scenario, twist):
    """Commands at the limits: the part's speed measured from its poses (20 ms apart), servo lag and
    catch-up included, stays within 2 % of the limits (`speed_cap_fraction`)."""
    _, samples = _closed_loop(scenario, np.array(twist, float), 2.0)
    v = [np.linalg.norm(b[1][:3] - a[1][:3]) / (b[0] - a[0]) for a, b in zip(samples, samples[1:])]
    w = [RotationMatrix(_rotation(b[1]) @ _rotation(a[1]).T).ToAngleAxis().angle() / (b[0] - a[0])
         for a, b in zip(samples, samples[1:])]
    assert max(v) <= 1.02 * scenario.diff_ik.max_linear_speed_m_s, max(v)
    assert max(w) <= 1.02 * scenario.diff_ik.max_angular_speed_rad_s, max(w)


def test_a_turn_driven_into_the_joint_limits_never_swings_the_part_aside(scenario):
    """A long fast turn runs the wrist into its limits; the least-squares cost would then trade the
    turn for a swing of the part's centre. The centre's speed stays within the bound on motion
    nobody asked for (plus the acceleration-limited come-down of one period)."""
    ik, samples = _closed_loop(scenario, np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0]), 8.0)
    bound = scenario.diff_ik.max_unrequested_linear_m_s
    come_down = scenario.diff_ik.joint_acceleration_rad_s2 * scenario.control_period_s * 1.0  # <= 1 m lever
    speeds = [np.linalg.norm(b[1][:3] - a[1][:3]) / (b[0] - a[0]) for a, b in zip(samples, samples[1:])]
    assert max(speeds) <= bound + come_down, max(speeds)


@pytest.mark.parametrize("axis", [3, 4, 5])
def test_a_fast_turn_in_free_space_keeps_the_part_centre_in_place(scenario, axis):
    """The turn is about the part's centre: with the linear half of the twist weighted on its own
    (`linear_tracking_weight`) and the backstop off, the centre moves at most 5 cm/s while the
    part starts turning at 0.8 rad/s, and at most 3.5 cm/s once it turns (one cost alone: 0.19-0.30)."""
    import copy

    s = copy.deepcopy(scenario)
    s.diff_ik.max_unrequested_linear_m_s = s.diff_ik.max_unrequested_angular_rad_s = 0.0
    twist = np.zeros(6)
    twist[axis] = 0.8
    _, samples = _closed_loop(s, twist, 1.0)
    speeds = np.array([np.linalg.norm(b[1][:3] - a[1][:3]) / (b[0] - a[0]) for a, b in zip(samples, samples[1:])])
    assert speeds.max() <= 0.05, speeds.max()
    assert speeds[-25:].max() <= 0.035, speeds[-25:].max()


def test_zero_twist_means_no_motion(scenario, controller):
    v, status, _ = controller.solve(Q_FREE, np.zeros(7), np.zeros(6))
    assert np.allclose(v, 0.0, atol=1e-9)
    assert status == FollowStatus.FOLLOWING


def test_non_finite_twist_is_treated_as_zero(controller):
    v, status, _ = controller.solve(Q_FREE, np.zeros(7), np.array([np.nan, 0, 0, 0, np.inf, 0]))
    assert np.allclose(v, 0.0, atol=1e-9)
    assert status == FollowStatus.INVALID_INPUT


def test_non_finite_joint_angles_bring_the_joints_down_at_the_acceleration_limit(scenario, controller):
    """A corrupt measurement (NaN or inf joint angles) while moving: the joints slow at the
    acceleration limit, toward rest, and the plant is never given the angles (Drake would stop
    the process)."""
    dv = scenario.diff_ik.joint_acceleration_rad_s2 * scenario.control_period_s
    v = np.array([0.3, -0.3, 0.5 * dv, 0.0, -0.5 * dv, 0.2, -0.2])
    for bad in (np.nan, np.inf):
        q = Q_FREE.copy()
        q[3] = bad
        v_next, status, _ = controller.solve(q, v, np.array([0.05, 0, 0, 0, 0, 0]))
        assert status == FollowStatus.INVALID_INPUT
        expected = [0.3 - dv, -0.3 + dv, 0.0, 0.0, 0.0, 0.2 - dv, -0.2 + dv]
        assert np.allclose(v_next, expected, atol=1e-12), v_next
    # the controller still answers on good angles afterwards
    v_next, status, _ = controller.solve(Q_FREE, np.zeros(7), np.zeros(6))
    assert status == FollowStatus.FOLLOWING and not v_next.any()


def test_the_qp_is_drakes_system(controller):
    assert isinstance(controller.drake_system, DifferentialInverseKinematicsSystem)
    assert controller.drake_system.recipe().num_ingredients() == 6  # costs: 3, constraints: 3


def test_a_zero_twist_while_moving_brings_the_part_to_rest(scenario, controller):
    """Asked for nothing while still moving: within the acceleration limit the part's speed
    only falls, and the arm comes to rest (no joint centering keeps it going)."""
    v = controller.joint_velocity_limit * 0.5 * np.array([1, -1, 1, -1, 1, -1, 1])
    dv = scenario.diff_ik.joint_acceleration_rad_s2 * scenario.control_period_s
    plant = controller.control_plant
    context = plant.CreateDefaultContext()
    frame = plant.GetFrameByName("workpiece")

    def part_speed(q, v):
        plant.SetPositions(context, q)
        plant.SetVelocities(context, v)
        return np.linalg.norm(frame.CalcSpatialVelocityInWorld(context).get_coeffs())

    q = Q_FREE.copy()
    speed = part_speed(q, v)
    for _ in range(40):
        v_next, status, _ = controller.solve(q, v, np.zeros(6))
        assert status != FollowStatus.NO_SOLUTION
        assert np.all(np.abs(v_next - v) <= dv + 1e-9)
        q, v = q + v_next * scenario.control_period_s, v_next
        assert part_speed(q, v) <= speed + 1e-6
        speed = part_speed(q, v)
    assert np.allclose(v, 0.0, atol=1e-6)


def test_console_silencing_from_two_threads_leaves_the_console_open():
    """Controllers solving in two threads (the intent reference with --jobs 2) each close the console
    around Drake's solve. Forced into the worst order (B enters while A is inside, A leaves first),
    the process's standard output must still be the console afterwards: B waits for A."""
    import os
    import threading

    from rtcohand_drake.systems.diff_ik import _console_silenced

    before = os.fstat(1)
    a_inside, b_inside, a_left = threading.Event(), threading.Event(), threading.Event()

    def a():
        with _console_silenced():
            a_inside.set()
            b_inside.wait(0.3)  # without the turn-taking, B is inside by now and saved /dev/null
        a_left.set()

    def b():
        a_inside.wait()
        with _console_silenced():
            b_inside.set()
            a_left.wait(0.6)  # ... and restores it after A has restored the console

    threads = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = os.fstat(1)
    assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)
