"""The cell's plant: the Gen3, gripper and workpiece welded together, placed in the cell.

`add_cell_models(plant, cell)` is shared by the simulated station, the
hardware station's display plant, the controllers' own kinematic plant
(`make_control_plant`) and the clearance and scoring code, so every one of
them sees the same kinematics and geometry. The robot's frames and package
are in docs/interfaces.md.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from rtcohand_drake.cell.layout import Cell
from rtcohand_drake.cell.robot_files import (
    GEN3_URL,
    GRIPPER_URL,
    INSPECTOR_URL,
    MOLD_URL,
    SAFETY_GLASS_URL,
    TABLE_URL,
    WORKPIECE_URL,
    add_package,
)

GEN3_JOINTS = tuple(f"Actuator{i}" for i in range(1, 8))
GEN3_LINKS = ("base_link", "shoulder_link", "half_arm_1_link", "half_arm_2_link",
              "forearm_link", "spherical_wrist_1_link", "spherical_wrist_2_link",
              "bracelet_link", "end_effector_link")

CELL_URLS = {"table": TABLE_URL, "mold": MOLD_URL, "safety_glass": SAFETY_GLASS_URL,
             "inspector": INSPECTOR_URL}

# Workpiece held upright by its top long edge: the fingers close along the
# grasp frame's x across the part's 0.05 m thickness (part z), the part's y
# axis (0.10 m) points back up the approach axis (grasp -z), and its top edge
# sits 12 mm above the finger pads' centre. Pose of the workpiece centre in the
# gripper's grasp frame (grasp z = approach direction).
X_GRASP_WORKPIECE = RigidTransform(
    RotationMatrix(np.array([[0.0, 0.0, 1.0],     # columns: part x, y, z in the grasp frame
                             [-1.0, 0.0, 0.0],
                             [0.0, -1.0, 0.0]])),
    [0.0, 0.0, 0.05 - 0.012],
)


def pose_vector(X: RigidTransform) -> np.ndarray:
    """[x y z qw qx qy qz] of a RigidTransform."""
    q = X.rotation().ToQuaternion()
    return np.concatenate([X.translation(), [q.w(), q.x(), q.y(), q.z()]])


def add_cell_models(plant: MultibodyPlant, cell: Cell) -> dict:
    """Adds the Gen3, gripper, workpiece and cell to `plant` and welds them.

    Returns the model instances by name. Shared by the simulated station and
    the hardware station's display plant.
    """
    parser = Parser(plant)
    add_package(parser)
    world = plant.world_frame()
    (gen3,) = parser.AddModels(url=GEN3_URL)
    plant.RenameModelInstance(gen3, "gen3")
    plant.WeldFrames(world, plant.GetFrameByName("base_link", gen3), RigidTransform())
    (gripper,) = parser.AddModels(url=GRIPPER_URL)
    plant.WeldFrames(plant.GetFrameByName("end_effector_link", gen3),
                     plant.GetFrameByName("robotiq_base_link", gripper), RigidTransform())
    (workpiece,) = parser.AddModels(url=WORKPIECE_URL)
    plant.WeldFrames(plant.GetFrameByName("grasp_frame", gripper),
                     plant.GetFrameByName("workpiece", workpiece), X_GRASP_WORKPIECE)
    instances = {"gen3": gen3, "gripper": gripper, "workpiece": workpiece}
    poses = {"table": cell.table, "mold": cell.mold, "safety_glass": cell.safety_glass,
             "inspector": cell.inspector}
    for name, url in CELL_URLS.items():
        (instance,) = parser.AddModels(url=url)
        body = plant.GetBodyByName(name, instance) if plant.HasBodyNamed(name, instance) \
            else plant.get_body(plant.GetBodyIndices(instance)[0])
        plant.WeldFrames(world, body.body_frame(), poses[name].to_rigid_transform())
        instances[name] = instance
    return instances


def exclude_arm_self_collisions(plant: MultibodyPlant, scene_graph, instances: dict) -> None:
    """No contact among the arm, gripper and held workpiece.

    The primitive link shapes overlap near the joints; self-collision is left
    to the controller's joint limits. Contact of the arm, gripper and part with
    the table, mold and glass stays on.
    """
    bodies = []
    for name in ("gen3", "gripper", "workpiece"):
        bodies += [plant.get_body(i) for i in plant.GetBodyIndices(instances[name])]
    geometries = plant.CollectRegisteredGeometries(bodies)
    scene_graph.collision_filter_manager().Apply(CollisionFilterDeclaration().ExcludeWithin(geometries))


def eye_position(cell: Cell) -> np.ndarray:
    """The inspector's eye point in the world (the inspector model's `eye` frame)."""
    plant, instances = make_control_plant(cell)
    context = plant.CreateDefaultContext()
    return plant.GetFrameByName("eye", instances["inspector"]).CalcPoseInWorld(context).translation()


# Parsed control plants, by the cell's full description: the models are parsed once per process
# (a study's worker runs many runs), not once per caller and run.
_CONTROL_PLANTS: dict[str, tuple[MultibodyPlant, object]] = {}


def make_control_plant(cell: Cell) -> tuple[MultibodyPlant, object]:
    """A plant with the same kinematics, for controllers' own kinematic queries.

    Controllers never read the station's internal plant, so they work the same
    against the hardware station. The plant is finalized and shared: one per
    cell layout and process. Callers make their own contexts and never change
    the plant itself.
    """
    key = repr(cell)
    if key not in _CONTROL_PLANTS:
        plant = MultibodyPlant(time_step=0.0)
        instances = add_cell_models(plant, cell)
        plant.Finalize()
        _CONTROL_PLANTS[key] = (plant, instances)
    return _CONTROL_PLANTS[key]
