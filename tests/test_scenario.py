"""Scenario files: the built-in one loads; typos and wrong types are one-line errors."""

import subprocess
import sys

import numpy as np
import pytest

from rtcohand_drake.interfaces import POSITION_MEASURED
from rtcohand_drake.scenario import ScenarioError, builtin_scenarios, load_scenario


def test_builtin_inspection_loads():
    s = load_scenario("inspection")
    assert "inspection" in builtin_scenarios()
    assert s.name == "inspection"
    assert len(s.robot.q0_rad) == 7
    assert s.diff_ik.max_linear_speed_m_s <= 0.25  # ISO 10218 reduced speed
    assert s.scripted_motion, "the skeleton run needs a scripted motion"


def _write(tmp_path, text):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, expected", [
    ("diff_ik:\n  max_linear_speed_ms: 0.2\n", "diff_ik.max_linear_speed_ms: unknown key"),
    ("plant_time_stp_s: 0.002\n", "plant_time_stp_s: unknown key"),
    ("duration_s: fast\n", "duration_s: expected a finite number"),
    ("cell:\n  mold: {xyz: [0.4, 0.1]}\n", "cell.mold.xyz: expected 3 numbers, got 2"),
    ("robot:\n  q0_rad: [0, 0, 0]\n", "robot.q0_rad: expected 7 numbers"),
    ("duration_s: [1\n", "malformed YAML"),
    ("duration_s: -3\n", "duration_s must be > 0"),
    ("workspace: {min_xyz: [0, 0, 1], max_xyz: [1, 1, 0]}\n", "min_xyz must be below max_xyz"),
    ("safety: {mold_turn_height_m: -0.1}\n", "mold corridor heights and margin must be >= 0"),
    ("", "the file is empty"),
    ("duration_s: 30\nlog_rate_hz: 60\nduration_s: 40\n", "line 3: 'duration_s' is given twice"),
    ("policy: {output_gain: 0.0}\n", "policy.output_gain must be in [1, 5], got 0.0"),
    ("robot:\n  kp_nm_per_rad: [2000, 2000, 2000, -2000, 500, 500, 500]\n", "robot.kp_nm_per_rad and"),
])
def test_bad_scenario_is_one_line_naming_file_and_problem(tmp_path, text, expected):
    path = _write(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    assert expected in message


def test_unknown_scenario_name():
    with pytest.raises(ScenarioError, match="no such scenario"):
        load_scenario("no_such_cell")


def test_cli_reports_typo_in_one_line_with_status_2(tmp_path):
    path = _write(tmp_path, "diff_ik:\n  max_angular_sped_rad_s: 1.0\n")
    proc = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--scenario", str(path), "--no-meshcat"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert str(path) in lines[0] and "max_angular_sped_rad_s: unknown key" in lines[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("name", builtin_scenarios())
def test_every_builtin_scenario_runs_briefly(name):
    """As Drake's hardware_sim does: each named scenario builds its diagram and simulates a moment."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.diagram import build_run_diagram

    scenario = load_scenario(name)
    run = build_run_diagram(scenario)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(0.1)
    q = run.station.GetOutputPort(POSITION_MEASURED).Eval(run.station.GetMyContextFromRoot(
        simulator.get_context()))
    assert np.all(np.isfinite(q))
