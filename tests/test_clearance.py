"""Clearance between the robot and the cell: distances, their gradients, and the IK holding the arm clear."""

import numpy as np
import pytest

from rtcohand_drake.cell.clearance import CellClearance, ClosePair, hold_clearance
from rtcohand_drake.systems.diff_ik import FollowStatus, TwistToJointVelocity
from rtcohand_drake.scenario import load_scenario


def _pair(distance, gradient):
    return ClosePair(distance, np.asarray(gradient, float), "robot", "cell")


def test_far_or_receding_pairs_change_nothing():
    v = np.array([0.3, -0.2, 0.1, 0, 0, 0, 0.05])
    g = np.eye(7)[0]
    out, acted = hold_clearance(v, [_pair(0.1, -g)], 0.02, 0.2)  # closes at 0.3, may at (0.1 - 0.02) / 0.2
    assert not acted and np.array_equal(out, v)
    out, acted = hold_clearance(v, [_pair(0.0, g)], 0.02, 0.2)  # in contact, joint 1 moving away
    assert not acted and np.array_equal(out, v)


def test_inside_the_margin_the_approach_is_removed_and_nothing_is_pushed():
    g = np.array([1.0, 1.0, 0, 0, 0, 0, 0])
    v = np.array([-0.4, 0.1, 0.2, 0, 0, 0, 0])  # closes in at g.v = -0.3
    out, acted = hold_clearance(v, [_pair(0.01, g)], 0.02, 0.2)
    assert acted
    assert g @ out == pytest.approx(0.0, abs=1e-12)
    assert out[2] == pytest.approx(0.2)  # the motion that does not approach stays
    still, acted = hold_clearance(np.zeros(7), [_pair(-0.005, g)], 0.02, 0.2)
    assert not acted and np.array_equal(still, np.zeros(7))  # at rest in contact: not pushed away


def test_outside_the_margin_the_approach_rate_is_bounded():
    g = np.eye(7)[3] * 2.0
    out, acted = hold_clearance(-np.eye(7)[3], [_pair(0.05, g)], 0.02, 0.2)
    assert acted
    assert g @ out == pytest.approx(-(0.05 - 0.02) / 0.2)


def test_several_pairs_are_all_held():
    pairs = [_pair(0.0, [1, 0.5, 0, 0, 0, 0, 0]), _pair(0.0, [0, 1, -1, 0, 0, 0, 0])]
    out, acted = hold_clearance(np.array([-1.0, -1.0, 1.0, 0, 0, 0, 0]), pairs, 0.02, 0.2, passes=50)
    assert acted
    assert all(p.gradient @ out >= -1e-6 for p in pairs)


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("inspection")


def test_gradient_matches_finite_differences(scenario):
    """An arm pose with the upper arm over the mold (a real run's), cylinder links near boxes."""
    clearance = CellClearance(scenario.cell)
    q = np.array([-2.4877, -2.0395, 4.2759, -1.9847, -0.8838, -1.6013, 1.2816])
    pairs = {(p.robot, p.cell): p for p in clearance.close_pairs(q, 0.05)}
    rng = np.random.default_rng(0)
    for key in (("gen3::half_arm_2_link_drum", "table::top"), ("gen3::half_arm_2_link_drum", "mold::wall_ny")):
        assert key in pairs
        for _ in range(4):
            dq = rng.normal(0, 1e-4, 7)
            ahead = {(p.robot, p.cell): p.distance for p in clearance.close_pairs(q + dq, 0.05)}[key]
            behind = {(p.robot, p.cell): p.distance for p in clearance.close_pairs(q - dq, 0.05)}[key]
            predicted = pairs[key].gradient @ dq
            assert (ahead - behind) / 2 == pytest.approx(predicted, rel=0.05, abs=5e-7)


def test_the_part_in_the_mold_is_a_close_pair(scenario):
    pairs = CellClearance(scenario.cell).close_pairs(np.asarray(scenario.robot.q0_rad, float), 0.05)
    assert {p.cell for p in pairs} >= {"mold::floor", "mold::wall_px"}
    assert next(p for p in pairs if p.cell == "mold::floor").robot.startswith("workpiece")


def test_min_distance_names_the_pair(scenario):
    clearance = CellClearance(scenario.cell, ignore=(("workpiece", "mold"),))
    d, pair = clearance.min_distance(np.asarray(scenario.robot.q0_rad, float))
    assert "mold" not in pair.split(" / ")[1] or not pair.startswith("workpiece")
    assert d > 0.0


def test_ik_keeps_the_part_clear_of_the_mold_floor_when_driven_down(scenario):
    """Lift the part out, then command it straight back down: it stops where the first robot-cell
    pair (the fingertips over the mold's wall) reaches the clearance margin."""
    ik = TwistToJointVelocity(scenario.diff_ik, scenario.cell, scenario.robot.q0_rad, scenario.control_period_s)
    clearance = CellClearance(scenario.cell)
    dt = scenario.control_period_s
    q = np.asarray(scenario.robot.q0_rad, float)
    v = np.zeros(7)
    statuses, closest = [], np.inf
    for k in range(int(5.0 / dt)):
        down = k * dt >= 1.5
        twist = np.array([0, 0, -0.1 if down else 0.1, 0, 0, 0])
        v, status, _ = ik.solve(q, v, twist)
        q = q + v * dt
        if down:
            statuses.append(status)
            closest = min([closest] + [p.distance for p in clearance.close_pairs(q, 0.1)])
    margin = scenario.diff_ik.min_cell_clearance_m
    assert FollowStatus.CLEARANCE in statuses
    assert closest >= margin - 2e-3
    final = min(p.distance for p in clearance.close_pairs(q, 0.1))
    assert final == pytest.approx(margin, abs=3e-3)  # it came down to the margin and stopped there
