"""Builds the run diagram from the scenario, by named ports.

    gesture source -> CchpPolicy -> MovingAverageDownsampler -> SafetySupervisor
        -> TwistToJointVelocity (diff IK) -> station (simulated Gen3 or Kortex arm)

or, without a policy, a scripted twist source straight into the supervisor.
An operator system (Meshcat panel or scripted) feeds the supervisor's pause and
sensitivity input. `VectorLogSink`s record everything the run log needs, and a
`MeshcatVisualizer` (plus the hand/twist/status overlay) draws the run when a
Meshcat is given. `RunDiagram` keeps handles to the pieces.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from rtcohand_drake.diff_ik import FollowStatus, TwistToJointVelocity
from rtcohand_drake.filtering import MovingAverageDownsampler
from rtcohand_drake.operator_panel import MeshcatOperatorPanel, ScriptedOperator
from rtcohand_drake.run_log import RunLog
from rtcohand_drake.safety import Intervention, Mode, SafetySupervisor
from rtcohand_drake.scenario import Scenario
from rtcohand_drake.scripted import ScriptedTwist
from rtcohand_drake.station import eye_position, make_sim_station


@dc.dataclass
class RunDiagram:
    diagram: Diagram
    station: Diagram
    controller: TwistToJointVelocity
    supervisor: SafetySupervisor
    source: LeafSystem
    operator: LeafSystem
    loggers: dict  # name -> VectorLogSink
    policy: LeafSystem | None = None
    command_filter: MovingAverageDownsampler | None = None
    visualizer: MeshcatVisualizer | None = None
    overlay: LeafSystem | None = None
    gesture_source: str = "scripted"


def build_run_diagram(scenario: Scenario, source: LeafSystem | None = None, policy: LeafSystem | None = None,
                      operator: LeafSystem | None = None, meshcat: Meshcat | None = None,
                      station: Diagram | None = None, gesture_source: str | None = None) -> RunDiagram:
    """Wires a run. Without `policy`, `source` must offer `twist_request` (default: the scenario's script)."""
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", station or make_sim_station(scenario))
    controller = builder.AddNamedSystem("diff_ik", TwistToJointVelocity(scenario))
    R_WU = scenario.cell.user_frame.to_rigid_transform().rotation().matrix()
    command_period = (scenario.command_filter.command_period_s if scenario.command_filter.mode == "paper"
                      else 1.0 / scenario.policy.rate_hz)
    supervisor = builder.AddNamedSystem("safety", SafetySupervisor(
        scenario.safety, scenario.workspace, R_WU, eye_position(scenario), command_period,
        X_W_mold=scenario.cell.mold.to_rigid_transform()))
    if operator is None:
        operator = MeshcatOperatorPanel(meshcat, scenario.safety) if meshcat is not None else ScriptedOperator()
    operator = builder.AddNamedSystem("operator", operator)
    source = builder.AddNamedSystem("gesture_source" if policy is not None else "scripted_twist",
                                    source or ScriptedTwist(scenario.scripted_motion))

    connect = builder.Connect
    connect(operator.GetOutputPort("operator"), supervisor.GetInputPort("operator"))
    connect(source.GetOutputPort("gesture_status"), supervisor.GetInputPort("gesture_status"))
    connect(station.GetOutputPort("workpiece.pose"), supervisor.GetInputPort("workpiece.pose"))
    if source.HasInputPort("workpiece.pose"):  # a closed-loop source (the simulated operator) watches the part
        connect(station.GetOutputPort("workpiece.pose"), source.GetInputPort("workpiece.pose"))
    command_filter = None
    if policy is not None:
        policy = builder.AddNamedSystem("cchp_policy", policy)
        command_filter = builder.AddNamedSystem(
            "moving_average", MovingAverageDownsampler(scenario.command_filter, 1.0 / scenario.policy.rate_hz))
        connect(source.GetOutputPort("gesture_features"), policy.GetInputPort("gesture_features"))
        connect(source.GetOutputPort("gesture_features"), supervisor.GetInputPort("gesture_features"))
        connect(supervisor.GetOutputPort("resume_count"), policy.GetInputPort("resume_count"))
        if policy.HasInputPort("intended_twist") and source.HasOutputPort("intended_twist"):
            # A reference policy (operator_sim.IntentPolicy) reads what the simulated person means.
            connect(source.GetOutputPort("intended_twist"), policy.GetInputPort("intended_twist"))
        connect(supervisor.GetOutputPort("resume_count"), command_filter.GetInputPort("resume_count"))
        connect(policy.GetOutputPort("policy_mean"), command_filter.GetInputPort("policy_mean"))
        connect(command_filter.GetOutputPort("twist_request"), supervisor.GetInputPort("twist_request"))
    else:
        connect(source.GetOutputPort("twist_request"), supervisor.GetInputPort("twist_request"))
    connect(supervisor.GetOutputPort("twist_command"), controller.GetInputPort("twist_command"))
    connect(station.GetOutputPort("gen3.position_measured"), controller.GetInputPort("gen3.position_measured"))
    connect(controller.GetOutputPort("gen3.velocity_command"), station.GetInputPort("gen3.velocity_command"))

    robot_period = 1.0 / scenario.log_rate_hz
    log = lambda port, period: LogVectorOutput(port, builder, period)
    loggers = {
        "robot_q": log(station.GetOutputPort("gen3.position_measured"), robot_period),
        "robot_v": log(station.GetOutputPort("gen3.velocity_estimated"), robot_period),
        "robot_workpiece_pose": log(station.GetOutputPort("workpiece.pose"), robot_period),
        "command_twist": log(supervisor.GetOutputPort("twist_command"), scenario.safety.period_s),
        "safety_status": log(supervisor.GetOutputPort("status"), scenario.safety.period_s),
        "follow_status": log(controller.GetOutputPort("follow_status"), scenario.control_period_s),
    }
    if policy is not None:
        policy_period = 1.0 / scenario.policy.rate_hz
        loggers["policy_mean"] = log(policy.GetOutputPort("policy_mean"), policy_period)
        loggers["policy_std"] = log(policy.GetOutputPort("policy_std"), policy_period)
    visualizer = overlay = None
    if meshcat is not None:
        from rtcohand_drake.meshcat_overlay import RunOverlay

        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.GetOutputPort("query_object"), meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="cell"))
        overlay = builder.AddNamedSystem("overlay", RunOverlay(meshcat, scenario))
        connect(source.GetOutputPort("keypoints") if source.HasOutputPort("keypoints")
                else _nan_keypoints(builder), overlay.GetInputPort("keypoints"))
        connect(supervisor.GetOutputPort("twist_command"), overlay.GetInputPort("twist_command"))
        connect(supervisor.GetOutputPort("status"), overlay.GetInputPort("safety_status"))
        connect(station.GetOutputPort("workpiece.pose"), overlay.GetInputPort("workpiece.pose"))
    diagram = builder.Build()
    diagram.set_name("rtcohand_run")
    name = gesture_source or ("scripted" if policy is None else type(source).__name__)
    return RunDiagram(diagram, station, controller, supervisor, source, operator, loggers, policy,
                      command_filter, visualizer, overlay, name)


def _nan_keypoints(builder):
    from pydrake.systems.primitives import ConstantVectorSource

    return builder.AddNamedSystem("no_hand", ConstantVectorSource(np.full(63, np.nan))).get_output_port()


def _log_arrays(sink: VectorLogSink, root: Context):
    log = sink.FindLog(root)
    return log.sample_times().copy(), log.data().T.copy()


def _transition_events(log: RunLog, times, codes, describe) -> None:
    previous = None
    for t, code in zip(times, codes):
        if code != previous:
            kind, detail = describe(code, previous)
            if kind:
                log.add_event(t, kind, detail)
            previous = code


def collect_run_log(run: RunDiagram, root_context: Context, scenario: Scenario) -> RunLog:
    """Turns the log sinks' contents into a RunLog, with safety and IK events."""
    log = RunLog(scenario=scenario.name, gesture_source=run.gesture_source,
                 model=getattr(run.policy, "model_path", "") if run.policy is not None else "")
    log.robot_time, log.robot_q = _log_arrays(run.loggers["robot_q"], root_context)
    _, log.robot_v = _log_arrays(run.loggers["robot_v"], root_context)
    _, log.robot_workpiece_pose = _log_arrays(run.loggers["robot_workpiece_pose"], root_context)
    log.command_time, log.command_twist = _log_arrays(run.loggers["command_twist"], root_context)
    if "policy_mean" in run.loggers:
        log.policy_time, log.policy_mean = _log_arrays(run.loggers["policy_mean"], root_context)
        _, log.policy_std = _log_arrays(run.loggers["policy_std"], root_context)

    t, status = _log_arrays(run.loggers["safety_status"], root_context)
    modes = status[:, 0].round().astype(int)
    kinds = {Mode.PAUSED: "pause", Mode.WATCHDOG: "watchdog", Mode.RUNNING: "resume"}
    _transition_events(log, t, modes, lambda m, prev: (
        (kinds[Mode(m)], f"supervisor {Mode(m).name.lower()}") if prev is not None or m != Mode.RUNNING
        else (None, "")))
    acted = status[:, 2].round().astype(int)
    for flag, kind in ((Intervention.SPEED_CLAMP, "clamp"), (Intervention.WORKSPACE, "workspace"),
                       (Intervention.INSPECTOR_ZONE, "inspector_zone"), (Intervention.MOLD_EXIT, "mold_exit"),
                       (Intervention.NON_FINITE, "fault")):
        on = (acted & int(flag)) != 0
        _transition_events(log, t, on, lambda o, prev, kind=kind: (
            (kind, f"{kind} limit acting") if o else (None, "")))

    t, follow = _log_arrays(run.loggers["follow_status"], root_context)
    codes = follow[:, 0].round().astype(int)
    _transition_events(log, t, codes, lambda c, prev: (
        ("ik_" + FollowStatus(c).name.lower(), "differential IK " + FollowStatus(c).name.lower().replace("_", " "))
        if (prev is not None or c != FollowStatus.FOLLOWING) else (None, "")))
    log.events.sort(key=lambda e: e.time)
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
