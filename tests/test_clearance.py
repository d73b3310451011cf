"""Clearance between the robot and the cell: the scoring distance, and the IK holding the arm clear."""

import numpy as np
import pytest

from rtcohand_drake.cell.clearance import CellClearance
from rtcohand_drake.systems.diff_ik import FollowStatus, make_twist_to_joint_velocity
from rtcohand_drake.scenario import load_scenario


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("inspection")


def test_the_part_in_the_mold_is_closest_to_its_floor(scenario):
    d, pair = CellClearance(scenario.cell).min_distance(np.asarray(scenario.robot.q0_rad, float))
    assert pair.startswith("workpiece") and pair.endswith("mold::floor")
    assert 0.0 < d < 0.005  # resting 2 mm above the cavity floor


def test_min_distance_names_the_pair(scenario):
    clearance = CellClearance(scenario.cell, ignore=(("workpiece", "mold"),))
    d, pair = clearance.min_distance(np.asarray(scenario.robot.q0_rad, float))
    assert "mold" not in pair.split(" / ")[1] or not pair.startswith("workpiece")
    assert d > 0.0


def _drive(scenario, twist_at, duration_s):
    ik = make_twist_to_joint_velocity(scenario)
    clearance = CellClearance(scenario.cell)
    dt = scenario.control_period_s
    q = np.asarray(scenario.robot.q0_rad, float)
    v = np.zeros(7)
    out = []
    for k in range(int(round(duration_s / dt))):
        v, status, _ = ik.solve(q, v, twist_at(k * dt))
        q = q + v * dt
        out.append((k * dt, status, clearance.min_distance(q, 0.1)[0], ik.workpiece_pose(q).translation()))
    return out


def test_the_seated_part_lifts_straight_out_and_is_never_pushed(scenario):
    """Inside the margin from the start (2 mm above the floor, 8 mm from the walls): a lift
    is followed, and nothing pushes the part anywhere it was not asked to go."""
    start = make_twist_to_joint_velocity(scenario).workpiece_pose(np.asarray(scenario.robot.q0_rad, float))
    samples = _drive(scenario, lambda t: np.array([0, 0, 0.1, 0, 0, 0]), 1.5)
    assert all(s != FollowStatus.NO_SOLUTION for _, s, _, _ in samples)
    lift = samples[-1][3] - start.translation()
    assert lift[2] == pytest.approx(0.1 * 1.5, abs=0.02)
    assert np.linalg.norm(lift[:2]) < 0.005
    assert min(d for _, _, d, _ in samples) > 0.0


def test_ik_keeps_the_part_clear_of_the_mold_floor_when_driven_down(scenario):
    """Lift the part out, then command it straight back down: it stops where the first robot-cell
    pair (the fingertips over the mold's wall) reaches the clearance margin."""
    samples = _drive(scenario, lambda t: np.array([0, 0, -0.1 if t >= 1.5 else 0.1, 0, 0, 0]), 5.0)
    down = [(s, d) for t, s, d, _ in samples if t >= 1.5]
    margin = scenario.diff_ik.min_cell_clearance_m
    assert FollowStatus.CLEARANCE in {s for s, _ in down}
    assert min(d for _, d in down) >= margin - 2e-3
    assert down[-1][1] == pytest.approx(margin, abs=3e-3)  # it came down to the margin and stopped there
