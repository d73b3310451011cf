"""The arm's initial joint angles: the workpiece resting upright in the mold's cavity.

The scenario stores `robot.q0_rad`; this module computes it for a cell layout
(Drake `InverseKinematics`) and checks it. After moving the mold in a
scenario, print the new angles with

    python -m rtcohand_drake.initial_pose --scenario PATH.yaml
"""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import Solve

from rtcohand_drake.errors import InputError, run_cli
from rtcohand_drake.scenario import Scenario, load_scenario
from rtcohand_drake.cell.plant import make_control_plant

# The maker's "Home" posture (0, 15, 180, 230, 0, 55, 90 degrees; 230 = -130 within joint 4's limits), tool down.
GEN3_HOME_RAD = np.deg2rad([0.0, 15.0, 180.0, -130.0, 0.0, 55.0, 90.0])
# Gap between the workpiece's bottom face and the cavity floor at rest (m).
REST_GAP_M = 0.002
WORKPIECE_HALF_HEIGHT_M = 0.05  # the part stands on its 0.15 x 0.05 face; y (0.10 m) is vertical


def workpiece_rest_pose(plant, plant_context, mold_instance) -> RigidTransform:
    """X_W_workpiece when the part stands upright in the cavity: part y up, part x along the cavity."""
    X_W_floor = plant.GetFrameByName("cavity_floor", mold_instance).CalcPoseInWorld(plant_context)
    R_floor_part = RotationMatrix(np.array([[1.0, 0.0, 0.0],
                                            [0.0, 0.0, -1.0],
                                            [0.0, 1.0, 0.0]]))  # columns: part x, y, z in the floor frame
    return X_W_floor @ RigidTransform(R_floor_part, [0.0, 0.0, WORKPIECE_HALF_HEIGHT_M + REST_GAP_M])


def solve_initial_q(scenario: Scenario, q_guess: np.ndarray | None = None) -> np.ndarray:
    plant, instances = make_control_plant(scenario.cell)
    context = plant.CreateDefaultContext()
    X_W_target = workpiece_rest_pose(plant, context, instances["mold"])
    frame = plant.GetFrameByName("workpiece", instances["workpiece"])
    ik = InverseKinematics(plant, context, with_joint_limits=True)
    ik.AddPositionConstraint(frame, np.zeros(3), plant.world_frame(),
                             X_W_target.translation() - 1e-4, X_W_target.translation() + 1e-4)
    ik.AddOrientationConstraint(frame, RotationMatrix(), plant.world_frame(), X_W_target.rotation(), 1e-3)
    q_guess = GEN3_HOME_RAD if q_guess is None else np.asarray(q_guess, float)
    prog = ik.get_mutable_prog()
    prog.AddQuadraticErrorCost(np.eye(7), q_guess, ik.q())
    prog.SetInitialGuess(ik.q(), q_guess)
    result = Solve(prog)
    if not result.is_success():
        raise InputError(f"scenario {scenario.name}: no arm posture puts the workpiece in the mold "
                         f"(mold at {scenario.cell.mold.xyz}); move the mold within reach")
    return result.GetSolution(ik.q())


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.initial_pose", description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="inspection")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    scenario = load_scenario(args.scenario)
    q = solve_initial_q(scenario, scenario.robot.q0_rad if any(scenario.robot.q0_rad) else None)
    print("robot:\n  q0_rad: [" + ", ".join(f"{x:.6f}" for x in q) + "]")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.initial_pose"))


if __name__ == "__main__":
    entry_point()
