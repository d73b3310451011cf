"""The simulated station: ports, initial posture, holding still, run CLI and log."""

import subprocess
import sys

import h5py
import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from rtcohand_drake.cell.initial_pose import solve_initial_q, workpiece_rest_pose
from rtcohand_drake.run_log import read_run_log
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.cell.plant import make_control_plant
from rtcohand_drake.stations.sim import make_sim_station
from rtcohand_drake.interfaces import STATION_INPUTS, STATION_OUTPUTS, POSITION_MEASURED, QUERY_OBJECT, VELOCITY_COMMAND, VELOCITY_ESTIMATED, WORKPIECE_POSE

STATION_PORTS_IN = set(STATION_INPUTS)
STATION_PORTS_OUT = set(STATION_OUTPUTS)


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("inspection")


@pytest.fixture(scope="module")
def station(scenario):
    return make_sim_station(scenario)


def test_station_ports(station):
    ins = {station.get_input_port(i).get_name() for i in range(station.num_input_ports())}
    outs = {station.get_output_port(i).get_name() for i in range(station.num_output_ports())}
    assert ins == STATION_PORTS_IN
    assert outs == STATION_PORTS_OUT


def test_initial_posture_rests_part_in_mold_without_contact(scenario, station):
    context = station.CreateDefaultContext()
    pose = station.GetOutputPort(WORKPIECE_POSE).Eval(context)
    plant, instances = make_control_plant(scenario.cell)
    X_rest = workpiece_rest_pose(plant, plant.CreateDefaultContext(), instances["mold"])
    assert np.allclose(pose[:3], X_rest.translation(), atol=1e-3)
    query = station.GetOutputPort(QUERY_OBJECT).Eval(context)
    assert query.ComputePointPairPenetration() == []
    inspector = query.inspector()
    walls = [d.distance for d in query.ComputeSignedDistancePairwiseClosestPoints(0.02)
             if {"workpiece::box"} & {inspector.GetName(d.id_A), inspector.GetName(d.id_B)}
             and any("wall" in inspector.GetName(g) for g in (d.id_A, d.id_B))]
    assert len(walls) == 4 and min(walls) > 0.005  # about 8 mm clearance all round


def test_scenario_q0_is_the_solved_rest_posture(scenario):
    """q0 in the YAML file agrees with the IK for the file's mold pose (re-run initial_pose if not)."""
    q = solve_initial_q(scenario, scenario.robot.q0_rad)
    plant, instances = make_control_plant(scenario.cell)
    ctx = plant.CreateDefaultContext()
    frame = plant.GetFrameByName("workpiece", instances["workpiece"])
    plant.SetPositions(ctx, q)
    X_solved = frame.CalcPoseInWorld(ctx)
    plant.SetPositions(ctx, scenario.robot.q0_rad)
    X_file = frame.CalcPoseInWorld(ctx)
    assert np.allclose(X_solved.translation(), X_file.translation(), atol=1e-3)


def test_zero_command_holds_still(station, scenario):
    context = station.CreateDefaultContext()
    station.GetInputPort(VELOCITY_COMMAND).FixValue(context, np.zeros(7))
    Simulator(station, context).AdvanceTo(2.0)
    q = station.GetOutputPort(POSITION_MEASURED).Eval(context)
    v = station.GetOutputPort(VELOCITY_ESTIMATED).Eval(context)
    assert np.allclose(q, scenario.robot.q0_rad, atol=1e-4)
    assert np.allclose(v, 0.0, atol=1e-4)


def test_nan_velocity_command_is_no_motion(station, scenario):
    context = station.CreateDefaultContext()
    station.GetInputPort(VELOCITY_COMMAND).FixValue(context, np.full(7, np.nan))
    Simulator(station, context).AdvanceTo(0.5)
    q = station.GetOutputPort(POSITION_MEASURED).Eval(context)
    assert np.all(np.isfinite(q)) and np.allclose(q, scenario.robot.q0_rad, atol=1e-4)


def test_velocity_command_is_tracked(scenario):
    """In free space (the part lifted clear of the mold), joint velocities are tracked."""
    import copy

    from rtcohand_drake.cell.initial_pose import GEN3_HOME_RAD

    free = copy.deepcopy(scenario)
    free.robot.q0_rad = list(GEN3_HOME_RAD)
    station = make_sim_station(free)
    context = station.CreateDefaultContext()
    v_cmd = np.array([0.1, -0.05, 0.0, 0.05, 0.0, 0.1, 0.2])
    station.GetInputPort(VELOCITY_COMMAND).FixValue(context, v_cmd)
    Simulator(station, context).AdvanceTo(1.0)
    v = station.GetOutputPort(VELOCITY_ESTIMATED).Eval(context)
    assert np.allclose(v, v_cmd, atol=0.01)


def test_run_cli_headless_writes_log(tmp_path):
    log = tmp_path / "run.h5"
    proc = subprocess.run(
        [sys.executable, "-m", "rtcohand_drake.run", "--scenario", "inspection", "--gesture-source", "scripted",
         "--duration", "10",
         "--realtime-rate", "0", "--no-meshcat", "--log", str(log)],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "faces inspected" in proc.stdout
    with h5py.File(log) as f:
        q = f["/robot/q"][()]
        pose = f["/robot/workpiece_pose"][()]
        t = f["/robot/time"][()]
        assert q.shape[1] == 7 and pose.shape[1] == 7 and len(t) == len(q) == len(pose)
        assert np.median(np.diff(t)) <= 1 / 50 + 1e-9  # at least 50 Hz
        assert t[-1] == pytest.approx(10.0, abs=0.05)
        assert f["/command/twist"].shape[1] == 6
        for key in ("scenario", "model", "gesture_source", "completed", "faces_inspected", "completion_time"):
            assert key in f.attrs
        # The scripted motion starts by lifting the part straight up out of the mold.
        assert pose[-1, 2] > pose[0, 2] + 0.15
    assert not list(tmp_path.glob("*.partial"))
    back = read_run_log(log)  # the reader returns what the run wrote, extra attributes included
    assert np.array_equal(back.robot_q, q)
    assert back.extra_attrs["mold_touched"] is False and back.extra_attrs["seed"] == 0
    assert back.extra_attrs["mold_min_clearance_m"] > 0.0


@pytest.mark.parametrize("args, expected", [
    (["--duration", "-1"], "--duration must be a positive number"),
    (["--scenario", "nowhere"], "no such scenario"),
    (["--log", "/no/such/dir/run.h5"], "does not exist"),
    (["--realtime-rate", "fast"], "invalid float value"),
])
def test_run_cli_bad_arguments(args, expected):
    proc = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--no-meshcat", *args],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and expected in proc.stderr, proc.stderr


def test_mold_clearance_sees_wall_contact(scenario):
    from rtcohand_drake.analysis.inspection import mold_clearance

    q0 = np.asarray(scenario.robot.q0_rad)
    resting, _ = mold_clearance(scenario, np.array([0.0]), q0[None])
    assert 0.005 < resting < 0.010  # about 8 mm to each wall at rest
    swung = q0 + np.array([0.08, 0, 0, 0, 0, 0, 0])  # base joint turned: the part swings into a wall
    touching, when = mold_clearance(scenario, np.array([0.0, 1.0]), np.stack([q0, swung]))
    assert touching < 0.0 and when == 1.0


def test_default_run_ends_a_short_hold_after_all_six_faces(tmp_path):
    """No --duration: the built-in person works the task, and the run stops done_hold_s (3 s) after the
    last face counts (the live monitor and the run's score use the same rule), well before the cap."""
    log = tmp_path / "run.h5"
    proc = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--scenario", "inspection",
                           "--realtime-rate", "0", "--no-meshcat", "--log", str(log)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    with h5py.File(log) as f:
        assert bool(f.attrs["completed"])
        end, done = float(f.attrs["sim_duration_s"]), float(f.attrs["completion_time"])
    assert 3.0 - 0.05 <= end - done <= 3.0 + 0.05
    assert end < 180.0
