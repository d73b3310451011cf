"""Builds the run diagram from the scenario, by named ports.

    gesture source -> CchpPolicy -> MovingAverageDownsampler -> SafetySupervisor
        -> TwistToJointVelocity (diff IK) -> station (simulated Gen3 or Kortex arm)

or, without a policy, a scripted twist source straight into the supervisor.
An operator panel (Meshcat, or a schedule of pauses) feeds the supervisor's pause and
sensitivity input, through the pause hand sign (`PauseHandSign`, a thumbs-up held
still toggles the same pause) when the scenario's `hand_sign.enabled`. `VectorLogSink`s record everything the run log needs, and a
`MeshcatVisualizer` (plus the hand/twist/status overlay) draws the run when a
Meshcat is given. `RunDiagram` keeps handles to the pieces.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from rtcohand_drake.systems.diff_ik import FollowStatus, make_twist_to_joint_velocity
from rtcohand_drake.systems.hand_sign import PauseHandSign
from rtcohand_drake.systems.moving_average_downsampler import MovingAverageDownsampler
from rtcohand_drake.systems.operator_panel import MeshcatOperatorPanel, ScheduledOperatorPanel
from rtcohand_drake.run_log import RunLog
from rtcohand_drake.systems.safety import rules
from rtcohand_drake.systems.safety.rules import Mode
from rtcohand_drake.systems.safety.supervisor import SafetySupervisor
from rtcohand_drake.systems.inspection_monitor import InspectionMonitor
from rtcohand_drake.scenario import Scenario
from rtcohand_drake.systems.scripted_twist import ScriptedTwist
from rtcohand_drake.cell.plant import eye_position
from rtcohand_drake.stations.sim import make_sim_station
from rtcohand_drake.interfaces import FACES_INSPECTED, FOLLOW_STATUS, GESTURE_FEATURES, GESTURE_STATUS, HAND_SIGN, INTENDED_TWIST, KEYPOINTS, OPERATOR, POLICY_MEAN, POLICY_STD, POSITION_MEASURED, READ_VARIANCE, SPEED_SCALE, QUERY_OBJECT, RESUME_COUNT, SAFETY_STATUS, TWIST_COMMAND, TWIST_REQUEST, VELOCITY_COMMAND, VELOCITY_ESTIMATED, WORKPIECE_POSE


# Meshcat's starting view (world frame, m): three-quarter, over the inspector's right shoulder.
VIEW_CAMERA_W = np.array([1.1, 1.15, 1.0])
VIEW_TARGET_W = np.array([0.3, 0.1, 0.45])


@dc.dataclass
class RunDiagram:
    diagram: Diagram
    station: Diagram
    controller: LeafSystem  # the differential IK (systems.diff_ik.SOLVERS)
    supervisor: SafetySupervisor
    source: LeafSystem
    operator: LeafSystem
    loggers: dict  # name -> VectorLogSink
    policy: LeafSystem | None = None
    command_filter: MovingAverageDownsampler | None = None
    visualizer: MeshcatVisualizer | None = None
    overlay: LeafSystem | None = None
    gesture_source: str = "scripted"
    monitor: InspectionMonitor | None = None
    hand_sign: PauseHandSign | None = None


def build_run_diagram(scenario: Scenario, source: LeafSystem | None = None, policy: LeafSystem | None = None,
                      operator: LeafSystem | None = None, meshcat: Meshcat | None = None,
                      station: Diagram | None = None, gesture_source: str | None = None) -> RunDiagram:
    """Wires a run. Without `policy`, `source` must offer `twist_request` (default: the scenario's script)."""
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", station or make_sim_station(scenario))
    controller = builder.AddNamedSystem("diff_ik", make_twist_to_joint_velocity(scenario))
    R_WU = scenario.cell.user_frame.to_rigid_transform().rotation().matrix()
    command_period = (scenario.command_filter.command_period_s if scenario.command_filter.mode == "paper"
                      else 1.0 / scenario.policy.rate_hz)
    supervisor = builder.AddNamedSystem("safety", SafetySupervisor(
        scenario.safety, scenario.workspace, R_WU, eye_position(scenario.cell), command_period,
        X_W_mold=scenario.cell.mold.to_rigid_transform()))
    if operator is None:
        operator = MeshcatOperatorPanel(meshcat, scenario.safety) if meshcat is not None else ScheduledOperatorPanel()
    operator = builder.AddNamedSystem("operator", operator)
    source = builder.AddNamedSystem("gesture_source" if policy is not None else "scripted_twist",
                                    source or ScriptedTwist(scenario.scripted_motion))

    connect = builder.Connect
    keypoints = source.GetOutputPort(KEYPOINTS) if source.HasOutputPort(KEYPOINTS) else _nan_keypoints(builder)
    hand_sign = None
    if scenario.hand_sign.enabled:
        hand_sign = builder.AddNamedSystem("hand_sign", PauseHandSign(scenario.hand_sign))
        connect(keypoints, hand_sign.GetInputPort(KEYPOINTS))
        connect(operator.GetOutputPort(OPERATOR), hand_sign.GetInputPort(OPERATOR))
        connect(hand_sign.GetOutputPort(OPERATOR), supervisor.GetInputPort(OPERATOR))
    else:
        connect(operator.GetOutputPort(OPERATOR), supervisor.GetInputPort(OPERATOR))
    connect(source.GetOutputPort(GESTURE_STATUS), supervisor.GetInputPort(GESTURE_STATUS))
    connect(station.GetOutputPort(WORKPIECE_POSE), supervisor.GetInputPort(WORKPIECE_POSE))
    if source.HasInputPort(WORKPIECE_POSE):  # a closed-loop source (the simulated person) watches the part
        connect(station.GetOutputPort(WORKPIECE_POSE), source.GetInputPort(WORKPIECE_POSE))
    command_filter = None
    if policy is not None:
        policy = builder.AddNamedSystem("cchp_policy", policy)
        command_filter = builder.AddNamedSystem(
            "moving_average", MovingAverageDownsampler(scenario.command_filter, 1.0 / scenario.policy.rate_hz))
        connect(source.GetOutputPort(GESTURE_FEATURES), policy.GetInputPort(GESTURE_FEATURES))
        connect(source.GetOutputPort(GESTURE_FEATURES), supervisor.GetInputPort(GESTURE_FEATURES))
        connect(supervisor.GetOutputPort(RESUME_COUNT), policy.GetInputPort(RESUME_COUNT))
        if policy.HasOutputPort(READ_VARIANCE):
            connect(policy.GetOutputPort(READ_VARIANCE), supervisor.GetInputPort(READ_VARIANCE))
        if policy.HasInputPort(KEYPOINTS):  # a policy file that reads the hand's path and shape
            connect(source.GetOutputPort(KEYPOINTS), policy.GetInputPort(KEYPOINTS))
        if policy.HasInputPort(INTENDED_TWIST) and source.HasOutputPort(INTENDED_TWIST):
            # A reference policy (analysis.reference_policies.IntentPolicy) reads what the simulated person means.
            connect(source.GetOutputPort(INTENDED_TWIST), policy.GetInputPort(INTENDED_TWIST))
        connect(supervisor.GetOutputPort(RESUME_COUNT), command_filter.GetInputPort(RESUME_COUNT))
        connect(policy.GetOutputPort(POLICY_MEAN), command_filter.GetInputPort(POLICY_MEAN))
        connect(command_filter.GetOutputPort(TWIST_REQUEST), supervisor.GetInputPort(TWIST_REQUEST))
    else:
        connect(source.GetOutputPort(TWIST_REQUEST), supervisor.GetInputPort(TWIST_REQUEST))
    connect(supervisor.GetOutputPort(TWIST_COMMAND), controller.GetInputPort(TWIST_COMMAND))
    connect(station.GetOutputPort(POSITION_MEASURED), controller.GetInputPort(POSITION_MEASURED))
    connect(controller.GetOutputPort(VELOCITY_COMMAND), station.GetInputPort(VELOCITY_COMMAND))

    robot_period = 1.0 / scenario.log_rate_hz
    monitor = builder.AddNamedSystem("inspection", InspectionMonitor(eye_position(scenario.cell), robot_period))
    connect(station.GetOutputPort(WORKPIECE_POSE), monitor.GetInputPort(WORKPIECE_POSE))
    log = lambda port, period: LogVectorOutput(port, builder, period)
    loggers = {
        "robot_q": log(station.GetOutputPort(POSITION_MEASURED), robot_period),
        "robot_v": log(station.GetOutputPort(VELOCITY_ESTIMATED), robot_period),
        "robot_workpiece_pose": log(station.GetOutputPort(WORKPIECE_POSE), robot_period),
        "command_twist": log(supervisor.GetOutputPort(TWIST_COMMAND), scenario.safety.period_s),
        "safety_status": log(supervisor.GetOutputPort(SAFETY_STATUS), scenario.safety.period_s),
        "speed_scale": log(supervisor.GetOutputPort(SPEED_SCALE), scenario.safety.period_s),
        "follow_status": log(controller.GetOutputPort(FOLLOW_STATUS), scenario.control_period_s),
    }
    policy_period = 1.0 / scenario.policy.rate_hz
    if hand_sign is not None:
        loggers["hand_sign"] = log(hand_sign.GetOutputPort(HAND_SIGN), scenario.hand_sign.period_s)
    loggers["gesture_status"] = log(source.GetOutputPort(GESTURE_STATUS), policy_period)
    loggers["gesture_keypoints"] = log(keypoints, policy_period)
    if source.HasOutputPort(INTENDED_TWIST):  # a simulated or recorded person: what they mean
        loggers["gesture_intended"] = log(source.GetOutputPort(INTENDED_TWIST), policy_period)
    if policy is not None:
        loggers["policy_mean"] = log(policy.GetOutputPort(POLICY_MEAN), policy_period)
        loggers["policy_std"] = log(policy.GetOutputPort(POLICY_STD), policy_period)
        if policy.HasOutputPort(READ_VARIANCE):
            loggers["read_variance"] = log(policy.GetOutputPort(READ_VARIANCE), policy_period)
    visualizer = overlay = None
    if meshcat is not None:
        from rtcohand_drake.systems.overlay import RunOverlay

        visualizer = MeshcatVisualizer.AddToBuilder(
            builder, station.GetOutputPort(QUERY_OBJECT), meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="cell"))
        overlay = builder.AddNamedSystem("overlay", RunOverlay(meshcat, scenario.cell.user_frame.to_rigid_transform()))
        connect(keypoints, overlay.GetInputPort(KEYPOINTS))
        connect(supervisor.GetOutputPort(TWIST_COMMAND), overlay.GetInputPort(TWIST_COMMAND))
        connect(supervisor.GetOutputPort(SAFETY_STATUS), overlay.GetInputPort(SAFETY_STATUS))
        connect(station.GetOutputPort(WORKPIECE_POSE), overlay.GetInputPort(WORKPIECE_POSE))
        connect(source.GetOutputPort(GESTURE_STATUS), overlay.GetInputPort(GESTURE_STATUS))
        connect(monitor.GetOutputPort(FACES_INSPECTED), overlay.GetInputPort(FACES_INSPECTED))
        if policy is not None:
            connect(policy.GetOutputPort(POLICY_STD), overlay.GetInputPort(POLICY_STD))
        # A close three-quarter view from the inspector's side: the arm, the mold and the glass fill it.
        meshcat.SetCameraPose(VIEW_CAMERA_W, VIEW_TARGET_W)
    diagram = builder.Build()
    diagram.set_name("rtcohand_run")
    name = gesture_source or ("scripted" if policy is None else type(source).__name__)
    return RunDiagram(diagram, station, controller, supervisor, source, operator, loggers, policy,
                      command_filter, visualizer, overlay, name, monitor, hand_sign)


def _nan_keypoints(builder):
    from pydrake.systems.primitives import ConstantVectorSource

    return builder.AddNamedSystem("no_hand", ConstantVectorSource(np.full(63, np.nan))).get_output_port()


def _log_arrays(sink: VectorLogSink, root: Context):
    log = sink.FindLog(root)
    return log.sample_times().copy(), log.data().T.copy()


def _log_group(run: "RunDiagram", root: Context, names) -> tuple[np.ndarray, list[np.ndarray]]:
    """The logs of sinks that publish on one clock: their times and data, cut to the shortest.

    A run stopped from outside (Ctrl-C, a lost connection) can end between two sinks'
    publishes of the same instant, so one log may hold a sample more than the others.
    """
    logs = [_log_arrays(run.loggers[name], root) for name in names]
    n = min(len(t) for t, _ in logs)
    return logs[0][0][:n], [data[:n] for _, data in logs]


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
    log.robot_time, (log.robot_q, log.robot_v, log.robot_workpiece_pose) = _log_group(
        run, root_context, ("robot_q", "robot_v", "robot_workpiece_pose"))
    log.command_time, (log.command_twist, speed_scale) = _log_group(
        run, root_context, ("command_twist", "speed_scale"))
    log.command_speed_scale = speed_scale[:, 0]
    if "policy_mean" in run.loggers:
        names = ("policy_mean", "policy_std") + (("read_variance",) if "read_variance" in run.loggers else ())
        log.policy_time, policy = _log_group(run, root_context, names)
        log.policy_mean, log.policy_std = policy[:2]
        if len(policy) > 2:
            log.policy_read_variance = policy[2][:, 0]
    names = ("gesture_status", "gesture_keypoints") + (("gesture_intended",) if "gesture_intended" in run.loggers else ())
    log.gesture_time, gesture = _log_group(run, root_context, names)
    status, log.gesture_keypoints = gesture[:2]
    log.gesture_valid, log.gesture_frame_time = status[:, 0], status[:, 1]
    if len(gesture) > 2:
        log.gesture_intended = gesture[2]

    t, status = _log_arrays(run.loggers["safety_status"], root_context)
    modes = status[:, 0].round().astype(int)
    kinds = {Mode.PAUSED: "pause", Mode.WATCHDOG: "watchdog", Mode.RUNNING: "resume"}
    toggles = _sign_toggle_times(run, root_context)

    # A pause, or a resume out of one, names its source: the hand sign when the sign toggled
    # since the supervisor's mode last changed, else the operator panel.
    previous, since = None, -np.inf
    for t_now, m in zip(t, modes):
        if m == previous:
            continue
        if previous is not None or m != Mode.RUNNING:
            detail = f"supervisor {Mode(m).name.lower()}"
            if m == Mode.PAUSED or (previous == Mode.PAUSED and m == Mode.RUNNING):
                by_sign = np.any((toggles > since) & (toggles <= t_now + 1e-9))
                detail += " (source: hand sign)" if by_sign else " (source: operator panel)"
            log.add_event(t_now, kinds[Mode(m)], detail)
        previous, since = m, t_now
    acted = status[:, 2].round().astype(int)
    for rule in rules.RULES:  # the same table the supervisor applies
        on = (acted & int(rule.flag)) != 0
        _transition_events(log, t, on, lambda o, prev, kind=rule.event: (
            (kind, f"{kind} limit acting") if o else (None, "")))

    t, follow = _log_arrays(run.loggers["follow_status"], root_context)
    codes = follow[:, 0].round().astype(int)
    _transition_events(log, t, codes, lambda c, prev: (
        ("ik_" + FollowStatus(c).name.lower(), "differential IK " + FollowStatus(c).name.lower().replace("_", " "))
        if (prev is not None or c != FollowStatus.FOLLOWING) else (None, "")))
    log.events.sort(key=lambda e: e.time)
    return log


def _sign_toggle_times(run: RunDiagram, root: Context) -> np.ndarray:
    """When the pause hand sign toggled (s); empty without one."""
    if "hand_sign" not in run.loggers:
        return np.zeros(0)
    t, sign = _log_arrays(run.loggers["hand_sign"], root)
    counts = np.concatenate([[0.0], sign[:, 2]])
    # A log sample at t holds the state of the update before it, one sign period earlier.
    return t[np.diff(counts) > 0.5] - run.hand_sign.period_s


def peak_speeds(times: np.ndarray, poses: np.ndarray) -> tuple[float, float]:
    """Peak linear (m/s) and angular (rad/s) speed of the workpiece from logged poses."""
    from rtcohand_drake.cell.geometry import quaternion_to_matrix

    if len(times) < 2:
        return 0.0, 0.0
    dt = np.diff(times)
    lin = np.linalg.norm(np.diff(poses[:, :3], axis=0), axis=1) / dt
    R = quaternion_to_matrix(poses[:, 3:7])
    rel = np.einsum("kji,kjl->kil", R[:-1], R[1:])  # R_k^T R_{k+1}
    angle = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
    return float(lin.max()), float((angle / dt).max())
