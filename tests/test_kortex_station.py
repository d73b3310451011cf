"""The hardware station against the fake Kortex arm: units, angles, the full run, every fault."""

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from rtcohand_drake.stations import kortex as kortex_station
from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.errors import InputError, run_cli
from rtcohand_drake.stations.fake_kortex_arm import FakeKortexArm, FakeServerError
from rtcohand_drake.cell.geometry import quaternion_to_matrix
from rtcohand_drake.stations.kortex import make_kortex_station
from rtcohand_drake.stations.kortex_session import (
    HardwareFault,
    KortexSession,
    deg_s_to_rad_s,
    feedback_to_rad,
    load_kortex_api,
    rad_s_to_deg_s,
    wrap_to_pi,
)
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.interfaces import STATION_INPUTS, STATION_OUTPUTS, POSITION_COMMANDED, POSITION_MEASURED, QUERY_OBJECT, VELOCITY_COMMAND, VELOCITY_ESTIMATED, WORKPIECE_POSE

ROBOT_IP = "192.0.2.10"  # a documentation address: nothing real answers there
STATION_PORTS_IN = set(STATION_INPUTS)
STATION_PORTS_OUT = set(STATION_OUTPUTS)


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("inspection")


class SimClock:
    """The fake arm's clock: the simulator's time once there is one (deterministic runs)."""

    def __init__(self):
        self.simulator = None
        self.t = 0.0

    def __call__(self):
        return self.simulator.get_context().get_time() if self.simulator is not None else self.t


def hardware_run(scenario, clock=None, watchdog_timeout_s=0.1, **station_args):
    """A fake arm at the scenario's q0, the hardware station on it, the run diagram and its simulator."""
    sim_clock = SimClock() if clock is None else None
    arm = FakeKortexArm(scenario.robot.q0_rad, clock=clock or sim_clock)
    station = make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api,
                                  watchdog_timeout_s=watchdog_timeout_s, **station_args)
    run = build_run_diagram(scenario, station=station)
    simulator = Simulator(run.diagram)
    if sim_clock is not None:
        sim_clock.simulator = simulator
    simulator.Initialize()
    return arm, station, run, simulator


def at_time(simulator, t_trigger, action):
    """Runs `action()` once, at the end of the first simulator step at or after t_trigger."""
    done = []

    def monitor(context):
        if not done and context.get_time() >= t_trigger:
            done.append(True)
            action()

    simulator.set_monitor(monitor)


def forced_update(system, context):
    """One update of every discrete system in `system`, as the simulator would make."""
    state = system.AllocateDiscreteVariables()
    system.CalcForcedDiscreteVariableUpdate(context, state)
    context.SetDiscreteState(state)


def assert_ends_with_stop(arm):
    """Stop() is the last call to the arm's base, then the session closes and the transport disconnects."""
    assert arm.call_names("base")[-1] == "Stop", arm.call_names("base")[-5:]
    assert arm.call_names()[-3:] == ["Stop", "CloseSession", "disconnect"], arm.call_names()[-5:]


# --- units and angles --------------------------------------------------------------------------


def test_wrap_to_pi_range():
    a = wrap_to_pi(np.array([0.0, np.pi, -np.pi, 3 * np.pi, 2 * np.pi + 0.1, -0.1]))
    assert np.allclose(a, [0.0, np.pi, np.pi, np.pi, 0.1, -0.1])
    assert np.all(a > -np.pi) and np.all(a <= np.pi)


def test_speed_units():
    assert np.allclose(rad_s_to_deg_s([np.pi, -np.pi / 2]), [180.0, -90.0])
    assert np.allclose(deg_s_to_rad_s(rad_s_to_deg_s([0.3, -1.2])), [0.3, -1.2])


def test_limited_joints_map_into_their_range():
    """Joints 2, 4, 6 read in [0, 360) degrees come back in (-pi, pi]: 340 deg is -20 deg."""
    reading = np.array([0.0, 340.0, 0.0, 100.0, 0.0, 232.0, 0.0])
    q = feedback_to_rad(reading, np.zeros(7))
    assert np.allclose(q[[1, 3, 5]], np.radians([-20.0, 100.0, -128.0]))


def test_continuous_joints_take_the_angle_nearest_the_reference(scenario):
    """The scenario's q0 (joint 3 at 3.735 rad > pi) read back from its wrapped degrees."""
    q0 = np.asarray(scenario.robot.q0_rad)
    reading = np.mod(np.degrees(q0), 360.0)
    assert np.all((reading >= 0) & (reading < 360))
    assert np.allclose(feedback_to_rad(reading, q0), q0)
    shifted = q0 + 2 * np.pi * np.array([1, 0, -1, 0, 2, 0, 1])  # a continuous joint several turns away
    assert np.allclose(feedback_to_rad(reading, shifted), shifted)


@pytest.mark.parametrize("start_deg, step_deg", [(355.0, 10.0), (5.0, -10.0), (179.0, 3.0)])
def test_continuous_joints_unwrap_across_360(start_deg, step_deg):
    """A joint turning through 360 -> 0 (or back) keeps counting instead of jumping a turn."""
    q = np.radians(np.full(7, start_deg))
    q = feedback_to_rad(np.full(7, start_deg), q)
    for _ in range(5):
        q_prev = q
        q = feedback_to_rad(np.mod(np.degrees(q_prev) + step_deg, 360.0), q_prev)
        assert np.allclose((q - q_prev)[[0, 2, 4, 6]], np.radians(step_deg))


# --- the fake arm itself -----------------------------------------------------------------------


def test_fake_arm_integrates_speeds_and_wraps_feedback():
    clock = SimClock()
    arm = FakeKortexArm(np.radians([350.0, -10.0, 0, 0, 0, 0, 0]), clock=clock)
    with KortexSession(arm.api(), ROBOT_IP, watchdog_timeout_s=10.0) as session:
        session.send_joint_speeds([20.0, -5.0, 0, 0, 0, 0, 0])  # deg/s
        clock.t = 1.0
        position, velocity = session.read_feedback()
        assert np.allclose(position[:2], [10.0, 345.0])  # 370 -> 10, -15 -> 345
        assert np.allclose(velocity[:2], [20.0, -5.0])
        assert np.allclose(arm.joint_positions_rad()[:2], np.radians([370.0, -15.0]))
        with pytest.raises(HardwareFault, match="out of range"):  # above the 80 deg/s hard limit
            session.send_joint_speeds([81.0, 0, 0, 0, 0, 0, 0])
    assert_ends_with_stop(arm)


def test_fake_arm_refuses_commands_outside_single_level_servoing():
    arm = FakeKortexArm()
    api = arm.api()
    transport = api.TCPTransport()
    router = api.RouterClient(transport)
    transport.connect(ROBOT_IP, 10000)
    api.SessionManager(router).CreateSession(api.Session_pb2.CreateSessionInfo(username="admin", password="admin"))
    command = api.Base_pb2.JointSpeeds()
    command.joint_speeds.add(joint_identifier=0, value=1.0, duration=0)
    with pytest.raises(FakeServerError, match="single-level"):
        api.BaseClient(router).SendJointSpeedsCommand(command)
    with pytest.raises(AttributeError):  # message fields are fixed, as in protobuf
        command.speed = 1.0


# --- the station alone -------------------------------------------------------------------------


def test_station_ports_match_the_simulated_station(scenario):
    arm = FakeKortexArm(scenario.robot.q0_rad, clock=SimClock())
    with make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api) as station:
        ins = {station.get_input_port(i).get_name() for i in range(station.num_input_ports())}
        outs = {station.get_output_port(i).get_name() for i in range(station.num_output_ports())}
        assert ins == STATION_PORTS_IN and outs == STATION_PORTS_OUT
        context = station.CreateDefaultContext()
        assert np.allclose(station.GetOutputPort(POSITION_MEASURED).Eval(context), scenario.robot.q0_rad)
        # The workpiece rests in the mold at q0, as in the simulated station.
        from rtcohand_drake.stations.sim import make_sim_station

        sim = make_sim_station(scenario)
        expected = sim.GetOutputPort(WORKPIECE_POSE).Eval(sim.CreateDefaultContext())
        assert np.allclose(station.GetOutputPort(WORKPIECE_POSE).Eval(context), expected, atol=1e-6)
        query = station.GetOutputPort(QUERY_OBJECT).Eval(context)
        assert query.ComputePointPairPenetration() == []
    assert_ends_with_stop(arm)


def test_units_through_the_station(scenario):
    """rad/s in -> deg/s JointSpeeds (ids 0..6, duration 0) out; feedback degrees -> rad and rad/s."""
    clock = SimClock()
    arm = FakeKortexArm(scenario.robot.q0_rad, clock=clock)
    with make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api, watchdog_timeout_s=10.0) as station:
        context = station.CreateDefaultContext()
        v = np.array([0.1, -0.2, 0.3, -0.05, 0.4, -0.3, 0.5])  # rad/s
        station.GetInputPort(VELOCITY_COMMAND).FixValue(context, v)
        forced_update(station, context)
        (command,) = [c.args[0] for c in arm.calls_to("base") if c.name == "SendJointSpeedsCommand"]
        assert [s.joint_identifier for s in command.joint_speeds] == list(range(7))
        assert np.allclose([s.value for s in command.joint_speeds], np.degrees(v))
        assert all(s.duration == 0 for s in command.joint_speeds)
        clock.t = 0.5
        forced_update(station, context)  # reads the feedback after 0.5 s at v
        q = station.GetOutputPort(POSITION_MEASURED).Eval(context)
        assert np.allclose(q, np.asarray(scenario.robot.q0_rad) + 0.5 * v)
        assert np.allclose(station.GetOutputPort(VELOCITY_ESTIMATED).Eval(context), v)
        assert np.allclose(station.GetOutputPort(POSITION_COMMANDED).Eval(context),
                           q + scenario.control_period_s * v)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 2.0])  # 2 rad/s is above joint 1's 80 deg/s
def test_invalid_command_is_never_sent(scenario, bad):
    arm = FakeKortexArm(scenario.robot.q0_rad, clock=SimClock())
    with make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api, watchdog_timeout_s=10.0) as station:
        context = station.CreateDefaultContext()
        station.GetInputPort(VELOCITY_COMMAND).FixValue(context, [bad, 0, 0, 0, 0, 0, 0])
        forced_update(station, context)
        assert "SendJointSpeedsCommand" not in arm.call_names()
        assert arm.call_names("base")[-1] == "Stop"
        assert [e.kind for e in station.events] == ["fault"]
        assert "not sent, Stop() instead" in station.events[0].detail


# --- the full diagram --------------------------------------------------------------------------


def test_follows_the_simulated_station(scenario):
    """The scripted motion (lift, carry toward the glass, a quarter turn) on both stations.

    Tolerance: both stations are driven by the same velocity-level differential
    IK, which never corrects position, so any difference in the joint speeds it
    computes accumulates along the path. The difference comes from feedback
    delay, not from the simulated servo's dynamics: the hardware station's
    reading at one update reaches the IK at the next, one control period (20 ms)
    later than the simulated plant's state does, and the IK's Jacobian is
    evaluated that much further back along the path. Measured here: the
    difference grows with the distance travelled, about 1% of it (6 mm over
    0.63 m), and scales with the control period (2 mm at 10 ms, 14 mm at 40 ms),
    where servo dynamics would not. The bounds are about twice what is measured:
    2% of the distance travelled + 2 mm (the simulated servo's lag of about one
    10 ms plant step at 0.12 m/s), 0.03 rad of workpiece orientation, 0.04 rad
    per joint. A unit error (deg/s sent as rad/s) would be off by a factor 57.
    """
    duration = 12.0
    arm, station, run, simulator = hardware_run(scenario, watchdog_timeout_s=30.0)
    # The fake arm moves on the simulation clock; a wall-clock stall of this shared
    # test machine must not stop it, so this run's watchdog is long.
    with station:
        simulator.AdvanceTo(duration)
    hw = {k: run.loggers[k].FindLog(simulator.get_context()) for k in ("robot_q", "robot_workpiece_pose")}

    sim_run = build_run_diagram(scenario)
    sim_simulator = Simulator(sim_run.diagram)
    sim_simulator.AdvanceTo(duration)
    sim = {k: sim_run.loggers[k].FindLog(sim_simulator.get_context()) for k in ("robot_q", "robot_workpiece_pose")}

    assert np.allclose(hw["robot_q"].sample_times(), sim["robot_q"].sample_times())
    q_hw, q_sim = hw["robot_q"].data().T, sim["robot_q"].data().T
    p_hw, p_sim = hw["robot_workpiece_pose"].data().T, sim["robot_workpiece_pose"].data().T
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p_sim[:, :3], axis=0), axis=1))])
    assert travelled[-1] > 0.5  # the run really moved
    position_error = np.linalg.norm(p_hw[:, :3] - p_sim[:, :3], axis=1)
    assert np.all(position_error <= 0.02 * travelled + 0.002), position_error.max()
    R_hw, R_sim = quaternion_to_matrix(p_hw[:, 3:]), quaternion_to_matrix(p_sim[:, 3:])
    angle = np.arccos(np.clip((np.einsum("kij,kij->k", R_hw, R_sim) - 1) / 2, -1, 1))
    assert angle.max() < 0.03
    assert np.abs(q_hw - q_sim).max() < 0.04
    # Every command went out in deg/s within the hard limits; the run ended with Stop().
    speeds = [[s.value for s in c.args[0].joint_speeds] for c in arm.calls_to("base")
              if c.name == "SendJointSpeedsCommand"]
    assert len(speeds) == pytest.approx(duration / scenario.control_period_s, abs=2)
    assert np.abs(speeds).max() > 5.0  # deg/s, not rad/s
    assert_ends_with_stop(arm)
    assert np.allclose(arm.joint_speeds_deg_s(), 0.0)
    assert station.events == []


def test_dry_run_sends_no_motion_and_shows_the_arm(scenario):
    from pydrake.geometry import Meshcat, MeshcatParams

    sim_clock = SimClock()
    arm = FakeKortexArm(scenario.robot.q0_rad, clock=sim_clock)
    meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
    station = make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api, dry_run=True)
    run = build_run_diagram(scenario, meshcat=meshcat, station=station)
    simulator = Simulator(run.diagram)
    sim_clock.simulator = simulator
    with station:
        simulator.AdvanceTo(1.0)
        assert meshcat.HasPath("/drake/cell/gen3/shoulder_link")
    names = arm.call_names("base")
    assert "SendJointSpeedsCommand" not in names and "SetServoingMode" not in names
    assert set(names) == {"Stop"}  # at open and at close only
    assert arm.call_names("base_cyclic").count("RefreshFeedback") >= 1.0 / scenario.control_period_s
    assert np.allclose(arm.joint_positions_rad(), scenario.robot.q0_rad)
    assert_ends_with_stop(arm)


# --- the watchdog and every fault --------------------------------------------------------------


def test_watchdog_stops_a_silent_client():
    """No command for 100 ms -> Stop() within 100 ms + one 10 ms check period (+ scheduling slack)."""
    arm = FakeKortexArm()  # wall clock
    with KortexSession(arm.api(), ROBOT_IP) as session:
        session.send_joint_speeds([10.0, 0, 0, 0, 0, 0, 0])
        time.sleep(0.4)
        sent = [c for c in arm.calls_to("base") if c.name == "SendJointSpeedsCommand"][-1]
        (stop,) = [c for c in arm.calls_to("base") if c.name == "Stop" and c.wall > sent.wall]
        assert stop.thread == "kortex-watchdog"
        delay = stop.wall - sent.wall
        # 0.05 s of slack: a thread wake-up on this shared 2-core machine can be late.
        assert session.watchdog_timeout_s <= delay <= session.watchdog_timeout_s + session.watchdog_check_s + 0.05
        assert np.allclose(arm.joint_speeds_deg_s(), 0.0)
        assert [kind for _, kind, _ in session.pop_events()] == ["watchdog"]
    assert_ends_with_stop(arm)


def test_frozen_client_is_stopped_by_the_watchdog(scenario):
    """The control loop hangs inside a call; the watchdog stops the arm; the hung call times out."""
    arm, station, run, simulator = hardware_run(scenario, clock=time.monotonic)
    at_time(simulator, 2.0, lambda: arm.freeze(timeout_s=0.5))  # mid-lift: the arm is moving
    with station, pytest.raises(HardwareFault) as fault:
        simulator.AdvanceTo(5.0)
    assert ROBOT_IP in str(fault.value) and "timed out" in str(fault.value)
    assert "the arm was sent Stop()" in str(fault.value)
    sent = [c for c in arm.calls_to("base") if c.name == "SendJointSpeedsCommand"][-1]
    assert np.abs([s.value for s in sent.args[0].joint_speeds]).max() > 1.0  # it was moving when it froze
    first_stop = next(c for c in arm.calls_to("base") if c.name == "Stop" and c.wall > sent.wall)
    assert first_stop.thread == "kortex-watchdog"
    assert 0.1 <= first_stop.wall - sent.wall <= 0.1 + 0.01 + 0.05
    assert_ends_with_stop(arm)
    assert np.allclose(arm.joint_speeds_deg_s(), 0.0)
    assert {"watchdog", "fault"} <= {e.kind for e in station.events}


def test_timeout_stops_the_arm_and_raises(scenario):
    arm, station, run, simulator = hardware_run(scenario)
    at_time(simulator, 1.0, lambda: arm.timeout_next(1))
    with station, pytest.raises(HardwareFault) as fault:
        simulator.AdvanceTo(3.0)
    message = str(fault.value)
    assert ROBOT_IP in message and "timed out" in message and "the arm was sent Stop()" in message
    assert "\n" not in message
    assert simulator.get_context().get_time() < 1.1
    assert_ends_with_stop(arm)
    assert np.allclose(arm.joint_speeds_deg_s(), 0.0)


def test_dropped_connection_stops_and_says_stop_was_not_delivered(scenario):
    arm, station, run, simulator = hardware_run(scenario)
    at_time(simulator, 1.0, arm.drop_connection)
    with station, pytest.raises(HardwareFault) as fault:
        simulator.AdvanceTo(3.0)
    message = str(fault.value)
    assert ROBOT_IP in message and "connection lost" in message
    # The fake no longer answers: the message must not claim the arm stopped.
    assert "could not be delivered" in message and "emergency stop" in message
    assert_ends_with_stop(arm)  # attempted last, in order, although the link is gone
    assert all(c.outcome != "ok" for c in arm.calls[-3:])


def test_exception_in_the_diagram_stops_the_arm(scenario):
    arm, station, run, simulator = hardware_run(scenario)

    def broken(t):
        raise RuntimeError("a bug upstream of the station")

    at_time(simulator, 1.0, lambda: setattr(run.source, "twist_at", broken))
    with station, pytest.raises(RuntimeError, match="a bug upstream"):
        simulator.AdvanceTo(3.0)
    assert_ends_with_stop(arm)
    assert np.allclose(arm.joint_speeds_deg_s(), 0.0)


# --- the command line --------------------------------------------------------------------------


@pytest.fixture
def fake_arm_for_cli(monkeypatch, scenario):
    """The CLI's `--hardware` path with the fake arm in place of kortex_api (wall clock)."""
    arm = FakeKortexArm(scenario.robot.q0_rad)
    monkeypatch.setattr(kortex_station, "load_kortex_api", arm.api)
    return arm


CLI_ARGS = ["--hardware", "--robot-ip", ROBOT_IP, "--no-meshcat", "--gesture-source", "scripted",
            "--realtime-rate", "0"]


def test_cli_ctrl_c_stops_the_arm(fake_arm_for_cli, capsys):
    """Ctrl-C (a real SIGINT from outside) in the middle of the run: the arm stops, the session closes, exit 130."""
    import os
    import threading

    from rtcohand_drake import run as run_module

    # As in a terminal: a test runner started in the background inherits SIGINT ignored.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)

    def press_ctrl_c():  # once the arm is being commanded, as a person at the keyboard would
        deadline = time.monotonic() + 60
        while "SendJointSpeedsCommand" not in fake_arm_for_cli.call_names() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.2)
        os.kill(os.getpid(), signal.SIGINT)

    presser = threading.Thread(target=press_ctrl_c, daemon=True)
    presser.start()
    args = [a for a in CLI_ARGS if a not in ("--realtime-rate", "0")] + ["--realtime-rate", "1", "--duration", "30"]
    try:
        status = run_cli(run_module.main, args, prog="rtcohand_drake.run")
    finally:
        presser.join(timeout=5)
        signal.signal(signal.SIGINT, previous)
    assert status == 130
    assert "interrupted" in capsys.readouterr().err
    assert_ends_with_stop(fake_arm_for_cli)
    assert "SendJointSpeedsCommand" in fake_arm_for_cli.call_names()


def test_cli_fault_is_one_line_exit_2(fake_arm_for_cli, monkeypatch, capsys):
    from rtcohand_drake import run as run_module

    original = fake_arm_for_cli._feedback
    calls = []

    def feedback_then_timeout():
        calls.append(1)
        if len(calls) == 20:
            fake_arm_for_cli.timeout_next(1)
        return original()

    monkeypatch.setattr(fake_arm_for_cli, "_feedback", feedback_then_timeout)
    status = run_cli(run_module.main, [*CLI_ARGS, "--duration", "3"], prog="rtcohand_drake.run")
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1, err
    assert ROBOT_IP in err[0] and "timed out" in err[0]
    assert_ends_with_stop(fake_arm_for_cli)


def test_cli_dry_run(fake_arm_for_cli, capsys):
    from rtcohand_drake import run as run_module

    status = run_cli(run_module.main, [*CLI_ARGS, "--dry-run", "--duration", "0.5"], prog="rtcohand_drake.run")
    assert status == 0, capsys.readouterr().err
    assert set(fake_arm_for_cli.call_names("base")) == {"Stop"}
    assert_ends_with_stop(fake_arm_for_cli)


def test_missing_kortex_api_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "kortex_api", None)  # as if not installed, even where it is
    with pytest.raises(InputError, match=r"kortex_api is not installed: download kortex_api-2\.6\.0\.post3"):
        load_kortex_api()


def test_connection_and_login_failures_are_clear(scenario):
    arm = FakeKortexArm(robot_ip="192.0.2.99")
    with pytest.raises(HardwareFault, match=f"{ROBOT_IP}: cannot connect on TCP port 10000"):
        make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api)
    arm = FakeKortexArm()
    with pytest.raises(HardwareFault, match="cannot open a session"):
        make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api, credentials=("admin", "wrong"))
    assert arm.call_names()[-1] == "disconnect"


def test_failure_while_opening_closes_the_session(scenario, monkeypatch):
    arm = FakeKortexArm()

    def refuse(mode):
        raise FakeServerError("SetServoingMode: refused")

    monkeypatch.setattr(arm, "_set_servoing_mode", refuse)
    with pytest.raises(HardwareFault, match="SetServoingMode failed"):
        make_kortex_station(scenario, ROBOT_IP, client_factory=arm.api)
    assert_ends_with_stop(arm)


def test_exit_without_close_still_stops_the_arm():
    """An exit path that skipped close() (an uncaught exception) still ends in Stop() (atexit)."""
    script = (
        "import atexit\n"
        "from rtcohand_drake.stations.fake_kortex_arm import FakeKortexArm\n"
        "from rtcohand_drake.stations.kortex_session import KortexSession\n"
        "arm = FakeKortexArm()\n"
        "atexit.register(lambda: print(','.join(arm.call_names())))\n"  # runs after the session's hook
        f"KortexSession(arm.api(), {ROBOT_IP!r}).open().send_joint_speeds([5.0] + [0.0] * 6)\n"
        "raise RuntimeError('crash before close')\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "crash before close" in proc.stderr
    names = proc.stdout.strip().split(",")
    assert names[names.index("SendJointSpeedsCommand"):][-3:] == ["Stop", "CloseSession", "disconnect"]


@pytest.mark.parametrize("args, expected", [
    (["--hardware"], "--hardware needs --robot-ip"),
    (["--robot-ip", ROBOT_IP], "go with --hardware"),
    (["--hardware", "--robot-ip", ROBOT_IP, "--gesture-source", "scripted"], "kortex_api is not installed"),
])
def test_cli_hardware_argument_errors(args, expected):
    proc = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--no-meshcat", *args],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and expected in proc.stderr, proc.stderr
