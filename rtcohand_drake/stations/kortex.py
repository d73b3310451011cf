"""The hardware station: a real Kinova Gen3 behind the Kortex API, with the simulated station's ports.

`make_kortex_station(scenario, robot_ip)` opens a Kortex session to the arm
and returns a `KortexStation`, a Drake Diagram with exactly the ports of
`rtcohand_drake.stations.sim.make_sim_station`, so `build_run_diagram(...,
station=...)` swaps one for the other and nothing else changes:

Input ports
  gen3.velocity_command   (7) joint velocity command, rad/s

Output ports
  gen3.position_measured  (7) joint angles from the arm's feedback, rad
  gen3.velocity_estimated (7) joint velocities from the arm's feedback, rad/s
  gen3.position_commanded (7) where the last sent speeds take the joints by the next period, rad
  workpiece.pose          (7) [x y z qw qx qy qz] of the workpiece centre, world frame,
                          from the forward kinematics of the measured joint angles
  query_object            SceneGraph query object of the cell with the arm at its measured
                          angles (Meshcat shows the real arm; distance checks see it)

Timing: `KortexArmInterface` updates every `scenario.control_period_s`: it
reads the feedback (`BaseCyclicClient.RefreshFeedback`) and sends the input's
joint speeds (`BaseClient.SendJointSpeedsCommand`, deg/s, duration 0; never a
twist, since differential IK already produced joint speeds). Each of these
blocking calls takes about 25 ms over the network, so one update needs about
50 ms: below that period the simulator falls behind real time and each speed
is held longer than the controller planned (the loop closes on the measured
angles, so it stays stable, only less smooth). Hardware scenarios should use a
control period of at least 0.05 s; run the simulator at real-time rate 1.

The session itself (its safety rules, units and joint angles) is
`rtcohand_drake.stations.kortex_session`, which imports no Drake.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from rtcohand_drake.run_log import Event
from rtcohand_drake.scenario import Scenario
from rtcohand_drake.stations.kortex_session import (
    N_JOINTS,
    KortexSession,
    deg_s_to_rad_s,
    feedback_to_rad,
    load_kortex_api,
    rad_s_to_deg_s,
)
from rtcohand_drake.cell.plant import add_cell_models, exclude_arm_self_collisions, pose_vector
from rtcohand_drake.interfaces import (POSE_DIM, POSITION_COMMANDED, POSITION_MEASURED, QUERY_OBJECT,
                                       VELOCITY_COMMAND, VELOCITY_ESTIMATED, WORKPIECE_POSE)

class KortexArmInterface(LeafSystem):
    """The arm as a discrete system: reads feedback and sends joint speeds every period.

    Input  `gen3.velocity_command` (7) rad/s.
    Output `gen3.position_measured` (7) rad, `gen3.velocity_estimated` (7) rad/s,
           `gen3.position_commanded` (7) rad.
    The session (network client) is an attribute; the measured state is discrete state.
    """

    def __init__(self, session: KortexSession, q_initial: np.ndarray, v_initial: np.ndarray, period_s: float,
                 velocity_limit_rad_s: np.ndarray):
        super().__init__()
        self._session = session
        self._period = period_s
        self._v_limit = np.asarray(velocity_limit_rad_s, dtype=float)
        self.events: list[Event] = []  # faults and watchdog stops, on the simulation clock
        self._t0_wall: float | None = None
        self._t0_sim = 0.0
        self._t_last = 0.0
        self._command = self.DeclareVectorInputPort(VELOCITY_COMMAND, N_JOINTS)
        self._q = self.DeclareDiscreteState(np.asarray(q_initial, dtype=float))
        self._v = self.DeclareDiscreteState(np.asarray(v_initial, dtype=float))
        self._q_commanded = self.DeclareDiscreteState(np.asarray(q_initial, dtype=float))
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareForcedDiscreteUpdateEvent(self._update)  # one step on demand (tests, tools)
        self.DeclareStateOutputPort(POSITION_MEASURED, self._q)
        self.DeclareStateOutputPort(VELOCITY_ESTIMATED, self._v)
        self.DeclareStateOutputPort(POSITION_COMMANDED, self._q_commanded)

    def check_command(self, v_rad_s: np.ndarray) -> str | None:
        """Why a joint velocity command must not be sent, or None when it may."""
        if not np.all(np.isfinite(v_rad_s)):
            return f"non-finite joint velocity command {np.array2string(v_rad_s, precision=3)}"
        over = np.abs(v_rad_s) > self._v_limit + 1e-9
        if np.any(over):
            joints = ", ".join(str(i + 1) for i in np.flatnonzero(over))
            return f"joint velocity command above the speed limit on joint(s) {joints}"
        return None

    def _update(self, context, discrete_state):
        t = context.get_time()
        self.collect_session_events(t)
        try:
            position_deg, velocity_deg_s = self._session.read_feedback()
            q = feedback_to_rad(position_deg, context.get_discrete_state(self._q).get_value())
            v_sent = np.zeros(N_JOINTS)
            if not self._session.dry_run:
                v_command = np.asarray(self._command.Eval(context), dtype=float)
                reason = self.check_command(v_command)
                if reason is None:
                    self._session.send_joint_speeds(rad_s_to_deg_s(v_command))
                    v_sent = v_command
                else:
                    self._session.stop()
                    self._session.record_event("fault", f"{reason}: not sent, Stop() instead")
        finally:
            self.collect_session_events(t)
        discrete_state.set_value(self._q, q)
        discrete_state.set_value(self._v, deg_s_to_rad_s(velocity_deg_s))
        discrete_state.set_value(self._q_commanded, q + self._period * v_sent)

    def collect_session_events(self, t: float | None = None) -> None:
        """Moves the session's events (stamped on the wall clock) onto the simulation clock."""
        t = self._t_last if t is None else t
        now = time.monotonic()
        self._t_last = max(self._t_last, t)
        if self._t0_wall is None:
            self._t0_wall, self._t0_sim = now, t
        for wall, kind, detail in self._session.pop_events():
            # Events from the watchdog thread happen between updates; place them at
            # their wall-clock offset, never past this update.
            self.events.append(Event(min(t, self._t0_sim + max(0.0, wall - self._t0_wall)), kind, detail))


class BodyPoseFromPositions(LeafSystem):
    """Input `positions` (7) rad; output `pose` (7) [x y z qw qx qy qz] of one body, world frame."""

    def __init__(self, plant: MultibodyPlant, body_name: str, model_instance):
        super().__init__()
        self._plant = plant
        self._plant_context = plant.CreateDefaultContext()
        self._frame = plant.GetBodyByName(body_name, model_instance).body_frame()
        self._q = self.DeclareVectorInputPort("positions", plant.num_positions())
        self.DeclareVectorOutputPort("pose", POSE_DIM, self._calc)

    def _calc(self, context, output: BasicVector):
        self._plant.SetPositions(self._plant_context, self._q.Eval(context))
        output.SetFromVector(pose_vector(self._frame.CalcPoseInWorld(self._plant_context)))


class KortexStation(Diagram):
    """The hardware station diagram (see the module docstring); owns its session.

    `close()` (or leaving a `with` block) stops the arm and closes the session.
    """

    def __init__(self, scenario: Scenario, session: KortexSession, name: str = "gen3_station"):
        super().__init__()
        self.session = session
        builder = DiagramBuilder()
        scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
        # Display and kinematics plant: the cell with the arm's joints as its only positions.
        plant = MultibodyPlant(time_step=0.0)
        plant.RegisterAsSourceForSceneGraph(scene_graph)
        instances = add_cell_models(plant, scenario.cell)
        plant.Finalize()
        exclude_arm_self_collisions(plant, scene_graph, instances)
        self._plant = plant  # the pose systems below refer to it
        assert plant.num_positions() == N_JOINTS

        position_deg, velocity_deg_s = session.read_feedback()
        q_initial = feedback_to_rad(position_deg, np.asarray(scenario.robot.q0_rad, dtype=float))
        self.interface = builder.AddNamedSystem("kortex_arm", KortexArmInterface(
            session, q_initial, deg_s_to_rad_s(velocity_deg_s), scenario.control_period_s,
            plant.GetVelocityUpperLimits()))
        to_geometry = builder.AddNamedSystem("display_poses", MultibodyPositionToGeometryPose(plant))
        builder.Connect(self.interface.GetOutputPort(POSITION_MEASURED), to_geometry.get_input_port())
        builder.Connect(to_geometry.get_output_port(), scene_graph.get_source_pose_port(plant.get_source_id()))
        workpiece = builder.AddNamedSystem("workpiece_pose",
                                           BodyPoseFromPositions(plant, "workpiece", instances["workpiece"]))
        builder.Connect(self.interface.GetOutputPort(POSITION_MEASURED), workpiece.get_input_port())

        builder.ExportInput(self.interface.GetInputPort(VELOCITY_COMMAND), VELOCITY_COMMAND)
        for port in (POSITION_MEASURED, VELOCITY_ESTIMATED, POSITION_COMMANDED):
            builder.ExportOutput(self.interface.GetOutputPort(port), port)
        builder.ExportOutput(workpiece.get_output_port(), WORKPIECE_POSE)
        builder.ExportOutput(scene_graph.get_query_output_port(), QUERY_OBJECT)
        builder.BuildInto(self)
        self.set_name(name)

    @property
    def events(self) -> list[Event]:
        """Faults and watchdog stops so far, on the simulation clock (run log `/events`)."""
        self.interface.collect_session_events()
        return list(self.interface.events)

    def close(self) -> None:
        self.session.close()

    def __enter__(self) -> KortexStation:
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False


def make_kortex_station(scenario: Scenario, robot_ip: str, *, client_factory: Callable[[], object] | None = None,
                        dry_run: bool = False, credentials: tuple[str, str] = ("admin", "admin"),
                        watchdog_timeout_s: float = 0.1, name: str = "gen3_station") -> KortexStation:
    """Connects to the arm at `robot_ip` and builds the hardware station (see the module docstring).

    `client_factory()` returns the kortex_api classes (`load_kortex_api` by
    default; tests pass `FakeKortexArm(...).api`). The caller must `close()`
    the station (or use it in a `with` block) to stop the arm and end the session.
    """
    api = (client_factory or load_kortex_api)()
    session = KortexSession(api, robot_ip, credentials=credentials, dry_run=dry_run,
                            watchdog_timeout_s=watchdog_timeout_s).open()
    try:
        return KortexStation(scenario, session, name=name)
    except BaseException:
        session.close()
        raise
