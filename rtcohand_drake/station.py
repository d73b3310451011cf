"""The simulated Gen3 inspection station: a Drake diagram with named ports.

`make_sim_station(scenario)` builds a MultibodyPlant + SceneGraph with the
Kinova Gen3, a Robotiq 2F-85 (simplified) at `end_effector_link`, the
workpiece, the table, the mold, the safety glass and the inspector, and wraps
them in a Diagram whose ports are the station interface. The hardware station
(`rtcohand_drake.kortex_station`) serves the same port names.

Input ports
  gen3.velocity_command   (7) joint velocity command, rad/s

Output ports
  gen3.position_measured  (7) joint angles, rad
  gen3.velocity_estimated (7) joint velocities, rad/s
  gen3.position_commanded (7) the servo's integrated position target, rad
  workpiece.pose          (7) [x y z qw qx qy qz] of the workpiece centre, world frame
  query_object            SceneGraph query object (for visualisers and distance checks)

Modelling choices
- The workpiece is welded to the gripper's `grasp_frame` (the part is held and
  never released in this product), the fingers are welded closed: the plant's
  only degrees of freedom are the arm's seven joints.
- The arm runs a joint-space position-velocity servo like the real one's
  low-level controller: the velocity command is integrated into a position
  target, tracked by Drake's PD-controlled actuators (implicit in the discrete
  solver, clamped at the actuators' torque limits) plus gravity compensation.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.multibody.tree import JointActuatorIndex, PdControllerGains
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Demultiplexer

from rtcohand_drake.model_files import (
    GEN3_URL,
    GRIPPER_URL,
    INSPECTOR_URL,
    MOLD_URL,
    SAFETY_GLASS_URL,
    TABLE_URL,
    WORKPIECE_URL,
    add_package,
)
from rtcohand_drake.scenario import Scenario

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


def add_cell_models(plant: MultibodyPlant, scenario: Scenario) -> dict:
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
    cell = scenario.cell
    poses = {"table": cell.table, "mold": cell.mold, "safety_glass": cell.safety_glass,
             "inspector": cell.inspector}
    for name, url in CELL_URLS.items():
        (instance,) = parser.AddModels(url=url)
        body = plant.GetBodyByName(name, instance) if plant.HasBodyNamed(name, instance) \
            else plant.get_body(plant.GetBodyIndices(instance)[0])
        plant.WeldFrames(world, body.body_frame(), poses[name].to_rigid_transform())
        instances[name] = instance
    return instances


class VelocityServo(LeafSystem):
    """Integrates a joint velocity command into the PD servo's desired state.

    Input  `velocity_command` (n), rad/s; `position_measured` (n), rad.
    Output `desired_state` (2n) = [q_target, v_command]; `position_commanded` (n).
    The target never leads the measured position by more than `max_lead_rad`,
    so a blocked arm does not wind up a large error that it would later release.
    """

    def __init__(self, q0: np.ndarray, dt: float, max_lead_rad: float = 0.05):
        super().__init__()
        n = len(q0)
        self._dt = dt
        self._max_lead = max_lead_rad
        self._v_in = self.DeclareVectorInputPort("velocity_command", n)
        self._q_in = self.DeclareVectorInputPort("position_measured", n)
        self._q_target = self.DeclareDiscreteState(np.asarray(q0, float))
        self.DeclarePeriodicDiscreteUpdateEvent(dt, 0.0, self._update)
        self.DeclareVectorOutputPort("desired_state", 2 * n, self._calc_desired_state,
                                     prerequisites_of_calc={self.xd_ticket(), self.all_input_ports_ticket()})
        self.DeclareVectorOutputPort("position_commanded", n, self._calc_position,
                                     prerequisites_of_calc={self.xd_ticket()})

    def _command(self, context) -> np.ndarray:
        v = self._v_in.Eval(context)
        return np.where(np.isfinite(v), v, 0.0)  # a NaN command is no command

    def _update(self, context, discrete_state):
        q_target = context.get_discrete_state(self._q_target).get_value()
        q_next = q_target + self._dt * self._command(context)
        q = self._q_in.Eval(context)
        q_next = np.clip(q_next, q - self._max_lead, q + self._max_lead)
        discrete_state.set_value(self._q_target, q_next)

    def _calc_desired_state(self, context, output: BasicVector):
        q_target = context.get_discrete_state(self._q_target).get_value()
        output.SetFromVector(np.concatenate([q_target, self._command(context)]))

    def _calc_position(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._q_target).get_value())


class BodyPoseVector(LeafSystem):
    """Output `pose` (7) = [x y z qw qx qy qz] of one body, from the plant's body poses."""

    def __init__(self, plant: MultibodyPlant, body_name: str, model_instance):
        super().__init__()
        self._index = int(plant.GetBodyByName(body_name, model_instance).index())
        self._poses = self.DeclareAbstractInputPort("body_poses", plant.get_body_poses_output_port().Allocate())
        self.DeclareVectorOutputPort("pose", 7, self._calc)

    def _calc(self, context, output: BasicVector):
        output.SetFromVector(pose_vector(self._poses.Eval(context)[self._index]))


# Actuator torque limits (N·m), Kinova Gen3 published figures (reference/facts.md).
GEN3_EFFORT_LIMITS_NM = (39.0, 39.0, 39.0, 39.0, 9.0, 9.0, 9.0)


def configure_gen3_servo(plant: MultibodyPlant, gen3, scenario: Scenario) -> None:
    """PD gains on each Gen3 actuator (the plant then has a desired-state input).

    Actuators come from the URDF's transmissions; where a joint has none, one
    is added with the published torque limit.
    """
    kp, kd = scenario.robot.kp_nm_per_rad, scenario.robot.kd_nm_s_per_rad
    for i, name in enumerate(GEN3_JOINTS):
        joint = plant.GetJointByName(name, gen3)
        actuators = [plant.get_joint_actuator(JointActuatorIndex(a)) for a in range(plant.num_actuators())]
        actuators = [a for a in actuators if a.joint().index() == joint.index()]
        actuator = actuators[0] if actuators else plant.AddJointActuator(f"{name}_motor", joint, GEN3_EFFORT_LIMITS_NM[i])
        actuator.set_controller_gains(PdControllerGains(p=kp[i], d=kd[i]))


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


def make_sim_station(scenario: Scenario, name: str = "gen3_station") -> Diagram:
    """Builds the simulated station diagram for `scenario` (see module docstring)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=scenario.plant_time_step_s)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kLagged)
    instances = add_cell_models(plant, scenario)
    gen3 = instances["gen3"]
    configure_gen3_servo(plant, gen3, scenario)
    plant.Finalize()
    exclude_arm_self_collisions(plant, scene_graph, instances)
    plant.SetDefaultPositions(gen3, np.asarray(scenario.robot.q0_rad))

    n = plant.num_positions(gen3)
    state_split = builder.AddNamedSystem("gen3_state_split", Demultiplexer([n, n]))
    builder.Connect(plant.get_state_output_port(gen3), state_split.get_input_port())

    servo = builder.AddNamedSystem("gen3_servo", VelocityServo(np.asarray(scenario.robot.q0_rad),
                                                              scenario.plant_time_step_s))
    builder.Connect(state_split.get_output_port(0), servo.GetInputPort("position_measured"))
    builder.Connect(servo.GetOutputPort("desired_state"), plant.get_desired_state_input_port(gen3))

    gravity = builder.AddNamedSystem(
        "gen3_gravity_compensation", InverseDynamics(plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
    builder.Connect(plant.get_state_output_port(), gravity.get_input_port_estimated_state())
    builder.Connect(gravity.get_output_port_generalized_force(), plant.get_actuation_input_port(gen3))

    workpiece_pose = builder.AddNamedSystem("workpiece_pose", BodyPoseVector(plant, "workpiece", instances["workpiece"]))
    builder.Connect(plant.get_body_poses_output_port(), workpiece_pose.get_input_port())

    builder.ExportInput(servo.GetInputPort("velocity_command"), "gen3.velocity_command")
    builder.ExportOutput(state_split.get_output_port(0), "gen3.position_measured")
    builder.ExportOutput(state_split.get_output_port(1), "gen3.velocity_estimated")
    builder.ExportOutput(servo.GetOutputPort("position_commanded"), "gen3.position_commanded")
    builder.ExportOutput(workpiece_pose.get_output_port(), "workpiece.pose")
    builder.ExportOutput(scene_graph.get_query_output_port(), "query_object")
    diagram = builder.Build()
    diagram.set_name(name)
    return diagram


def eye_position(scenario: Scenario) -> np.ndarray:
    """The inspector's eye point in the world (the inspector model's `eye` frame)."""
    plant, instances = make_control_plant(scenario)
    context = plant.CreateDefaultContext()
    return plant.GetFrameByName("eye", instances["inspector"]).CalcPoseInWorld(context).translation()


def station_plant(station: Diagram) -> MultibodyPlant:
    return station.GetSubsystemByName("plant")


def make_control_plant(scenario: Scenario) -> tuple[MultibodyPlant, object]:
    """A plant with the same kinematics, for controllers' own kinematic queries.

    Controllers never read the station's internal plant, so they work the same
    against the hardware station.
    """
    plant = MultibodyPlant(time_step=0.0)
    instances = add_cell_models(plant, scenario)
    plant.Finalize()
    return plant, instances
