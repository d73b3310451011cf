"""Builds the run diagram: a twist source -> differential IK -> station, with loggers.

`build_run_diagram(scenario, ...)` wires the systems by their named ports and
adds Drake `VectorLogSink`s for the run log, and a `MeshcatVisualizer` when a
Meshcat is given. The returned `RunDiagram` keeps handles to the pieces a
caller needs after the simulation (the log sinks, the visualiser).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from rtcohand_drake.diff_ik import TwistToJointVelocity
from rtcohand_drake.run_log import RunLog
from rtcohand_drake.scenario import Scenario
from rtcohand_drake.scripted import ScriptedTwist
from rtcohand_drake.station import make_sim_station


@dc.dataclass
class RunDiagram:
    diagram: Diagram
    station: Diagram
    controller: TwistToJointVelocity
    source: object
    loggers: dict  # name -> VectorLogSink
    visualizer: MeshcatVisualizer | None = None
    gesture_source: str = "scripted"


def build_run_diagram(scenario: Scenario, meshcat: Meshcat | None = None, station: Diagram | None = None) -> RunDiagram:
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", station or make_sim_station(scenario))
    controller = builder.AddNamedSystem("diff_ik", TwistToJointVelocity(scenario))
    source = builder.AddNamedSystem("scripted_twist", ScriptedTwist(scenario.scripted_motion))
    builder.Connect(source.GetOutputPort("twist_command"), controller.GetInputPort("twist_command"))
    builder.Connect(station.GetOutputPort("gen3.position_measured"), controller.GetInputPort("gen3.position_measured"))
    builder.Connect(controller.GetOutputPort("gen3.velocity_command"), station.GetInputPort("gen3.velocity_command"))

    period = 1.0 / scenario.log_rate_hz
    loggers = {
        "robot_q": LogVectorOutput(station.GetOutputPort("gen3.position_measured"), builder, period),
        "robot_v": LogVectorOutput(station.GetOutputPort("gen3.velocity_estimated"), builder, period),
        "robot_workpiece_pose": LogVectorOutput(station.GetOutputPort("workpiece.pose"), builder, period),
        "command_twist": LogVectorOutput(source.GetOutputPort("twist_command"), builder,
                                                         scenario.control_period_s),
        "follow_status": LogVectorOutput(controller.GetOutputPort("follow_status"), builder,
                                                         scenario.control_period_s),
    }
    visualizer = None
    if meshcat is not None:
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.GetOutputPort("query_object"), meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="cell"))
    diagram = builder.Build()
    diagram.set_name("rtcohand_run")
    return RunDiagram(diagram, station, controller, source, loggers, visualizer)


def _log_arrays(sink: VectorLogSink, root: Context):
    log = sink.FindLog(root)
    return log.sample_times().copy(), log.data().T.copy()


def collect_run_log(run: RunDiagram, root_context: Context, scenario: Scenario) -> RunLog:
    """Turns the log sinks' contents into a RunLog (robot, command and IK events)."""
    log = RunLog(scenario=scenario.name, gesture_source=run.gesture_source)
    t, log.robot_q = _log_arrays(run.loggers["robot_q"], root_context)
    log.robot_time = t
    _, log.robot_v = _log_arrays(run.loggers["robot_v"], root_context)
    _, log.robot_workpiece_pose = _log_arrays(run.loggers["robot_workpiece_pose"], root_context)
    log.command_time, log.command_twist = _log_arrays(run.loggers["command_twist"], root_context)
    status_t, status = _log_arrays(run.loggers["follow_status"], root_context)
    previous = 0
    for t_k, (code, ratio) in zip(status_t, status):
        code = int(round(code))
        if code != previous:
            from rtcohand_drake.diff_ik import FollowStatus

            kind = "ik_" + FollowStatus(code).name.lower() if code else "ik_following"
            log.add_event(t_k, kind, f"achieved {ratio:.2f} of the commanded twist")
            previous = code
    return log


def peak_speeds(times: np.ndarray, poses: np.ndarray) -> tuple[float, float]:
    """Peak linear (m/s) and angular (rad/s) speed of the workpiece from logged poses."""
    from rtcohand_drake.inspection import quaternion_to_matrix

    if len(times) < 2:
        return 0.0, 0.0
    dt = np.diff(times)
    lin = np.linalg.norm(np.diff(poses[:, :3], axis=0), axis=1) / dt
    R = quaternion_to_matrix(poses[:, 3:7])
    rel = np.einsum("kji,kjl->kil", R[:-1], R[1:])  # R_k^T R_{k+1}
    angle = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
    return float(lin.max()), float((angle / dt).max())
