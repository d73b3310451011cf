"""The simulated Gen3 inspection station: a Drake diagram with named ports.

`make_sim_station(scenario)` builds a MultibodyPlant + SceneGraph with the
Kinova Gen3, a Robotiq 2F-85 (simplified) at `end_effector_link`, the
workpiece, the table, the mold, the safety glass and the inspector, and wraps
them in a Diagram whose ports are the station interface. The hardware station
(`rtcohand_drake.stations.kortex`) serves the same port names.

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
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.multibody.tree import JointActuatorIndex, PdControllerGains
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Demultiplexer

from rtcohand_drake.cell.plant import add_cell_models, exclude_arm_self_collisions, pose_vector, GEN3_JOINTS
from rtcohand_drake.scenario import Scenario
from rtcohand_drake.interfaces import (POSE_DIM, POSITION_COMMANDED, POSITION_MEASURED, QUERY_OBJECT,
                                       VELOCITY_COMMAND, VELOCITY_ESTIMATED, WORKPIECE_POSE)

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
        finite = np.isfinite(v)
        return v if finite.all() else np.where(finite, v, 0.0)  # a NaN command is no command

    def _update(self, context, discrete_state):
        q_target = context.get_discrete_state(self._q_target).get_value()
        q_next = q_target + self._dt * self._command(context)
        q = self._q_in.Eval(context)
        q_next = np.minimum(np.maximum(q_next, q - self._max_lead), q + self._max_lead)  # np.clip's arithmetic
        discrete_state.set_value(self._q_target, q_next)

    def _calc_desired_state(self, context, output: BasicVector):
        q_target = context.get_discrete_state(self._q_target).get_value()
        output.SetFromVector(np.concatenate([q_target, self._command(context)]))

    def _calc_position(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._q_target).get_value())


class BodyPoseVector(LeafSystem):
    """Output `pose` (7) = [x y z qw qx qy qz] of one body, from the plant's positions.

    Input `positions` (the plant's positions). The plant's own kinematics on a context of
    this system's (the same calculation as the plant's `body_poses` port, which would hand
    every body's pose to Python at each evaluation)."""

    def __init__(self, plant: MultibodyPlant, body_name: str, model_instance):
        super().__init__()
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._body = plant.GetBodyByName(body_name, model_instance)
        self._q = self.DeclareVectorInputPort("positions", plant.num_positions())
        self.DeclareVectorOutputPort("pose", POSE_DIM, self._calc)

    def _calc(self, context, output: BasicVector):
        self._plant.SetPositions(self._plant_context, self._q.Eval(context))
        output.SetFromVector(pose_vector(self._plant.EvalBodyPoseInWorld(self._plant_context, self._body)))


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


def make_sim_station(scenario: Scenario, name: str = "gen3_station") -> Diagram:
    """Builds the simulated station diagram for `scenario` (see module docstring)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=scenario.plant_time_step_s)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kLagged)
    instances = add_cell_models(plant, scenario.cell)
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
    assert plant.num_positions() == n, "the arm's joints are the plant's only positions"
    builder.Connect(state_split.get_output_port(0), workpiece_pose.get_input_port())

    builder.ExportInput(servo.GetInputPort("velocity_command"), VELOCITY_COMMAND)
    builder.ExportOutput(state_split.get_output_port(0), POSITION_MEASURED)
    builder.ExportOutput(state_split.get_output_port(1), VELOCITY_ESTIMATED)
    builder.ExportOutput(servo.GetOutputPort("position_commanded"), POSITION_COMMANDED)
    builder.ExportOutput(workpiece_pose.get_output_port(), WORKPIECE_POSE)
    builder.ExportOutput(scene_graph.get_query_output_port(), QUERY_OBJECT)
    diagram = builder.Build()
    diagram.set_name(name)
    return diagram
