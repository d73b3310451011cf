"""The inspection task, measured from the workpiece's trajectory.

A face counts as inspected when its outward normal points within
`max_angle_deg` (35 degrees) of the direction from the workpiece centre to
the inspector's eye, continuously for at least `hold_s` (0.5 s). The task is
complete when all six faces have been inspected; its completion time is the
moment the last face's hold is over.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.geometry import Role

from rtcohand_drake.cell.faces import FACES
from rtcohand_drake.cell.geometry import quaternion_to_matrix


@dc.dataclass
class InspectionResult:
    inspected_at: dict  # face name -> time (s) its hold completed, or NaN
    faces_inspected: int
    completed: bool
    completion_time: float


_NORMALS_E = np.array([face[1] for face in FACES], float)  # (6, 3)


def face_angles_deg(poses: np.ndarray, eye_xyz) -> np.ndarray:
    """(K, 6) angle between each face's outward normal and the line of sight to the eye.

    Pose by pose in Python floats: the live monitor (one pose each log period) and the
    scoring of a whole run log then count with the very same arithmetic."""
    poses = np.atleast_2d(np.asarray(poses, float))
    return np.array([_one_pose_face_angles_deg(p, eye_xyz) for p in poses]).reshape(len(poses), len(FACES))


def _one_pose_face_angles_deg(pose: np.ndarray, eye_xyz) -> np.ndarray:
    """(6) `face_angles_deg` of one pose [x y z qw qx qy qz]."""
    R = quaternion_to_matrix(pose[3:7]).tolist()
    e = [float(eye_xyz[i]) - float(pose[i]) for i in range(3)]
    n = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    e = [c / n for c in e]
    out = []
    for nx, ny, nz in _NORMALS_E.tolist():
        cos = 0.0
        for i in range(3):
            cos += (R[i][0] * nx + R[i][1] * ny + R[i][2] * nz) * e[i]
        out.append(math.degrees(math.acos(min(max(cos, -1.0), 1.0))))
    return np.array(out)


MAX_ANGLE_DEG = 35.0
HOLD_S = 0.5


def advance_holds(start: np.ndarray, inspected_at: np.ndarray, t: float, visible: np.ndarray,
                  hold_s: float = HOLD_S) -> tuple[np.ndarray, np.ndarray]:
    """One sample of the hold rule for the six faces: (time each face's current view began, NaN
    if out of view; time each face's hold completed, NaN if not yet). Used after a run
    (`measure_inspection`) and live (`systems.inspection_monitor`), so both count alike."""
    start = np.where(visible, np.where(np.isnan(start), t, start), np.nan)
    inspected_at = np.where(np.isnan(inspected_at) & visible & (t - start >= hold_s), t, inspected_at)
    return start, inspected_at


def measure_inspection(times: np.ndarray, poses: np.ndarray, eye_xyz,
                       max_angle_deg: float = MAX_ANGLE_DEG, hold_s: float = HOLD_S) -> InspectionResult:
    times = np.asarray(times, float)
    start = np.full(len(FACES), np.nan)
    done_at = np.full(len(FACES), np.nan)
    if len(times):
        visible = face_angles_deg(poses, eye_xyz) <= max_angle_deg
        for k, t in enumerate(times):
            start, done_at = advance_holds(start, done_at, float(t), visible[k], hold_s)
    inspected_at = {face[0]: float(done_at[f]) for f, face in enumerate(FACES)}
    done = [t for t in inspected_at.values() if np.isfinite(t)]
    completed = len(done) == len(FACES)
    return InspectionResult(inspected_at, len(done), completed, max(done) if completed else float("nan"))


def mold_clearance(scenario, times: np.ndarray, q: np.ndarray, rate_hz: float = 25.0) -> tuple[float, float]:
    """Smallest signed distance (m) between the workpiece and the mold's walls while close, and when.

    Replays the logged joint angles through the cell's geometry (Drake's
    SceneGraph signed-distance queries), at `rate_hz`. A value <= 0 means the
    part touched the mold. Returns (min distance, its time); (inf, nan) if
    the part was never within 5 cm of the mold.
    """
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    from rtcohand_drake.cell.plant import add_cell_models

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    instances = add_cell_models(plant, scenario.cell)
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    sg_context = scene_graph.GetMyContextFromRoot(context)
    inspector = scene_graph.model_inspector()

    def geometries(name):
        ids = []
        for body in plant.GetBodyIndices(instances[name]):
            frame = plant.GetBodyFrameIdOrThrow(body)
            ids += list(inspector.GetGeometries(frame, Role.kProximity))
        return ids

    part = geometries("workpiece")
    mold = [g for g in geometries("mold") if "wall" in inspector.GetName(g)]  # the cavity walls, not its floor
    best, when = float("inf"), float("nan")
    if len(times) == 0:
        return best, when
    stride = max(1, int(round(1.0 / (rate_hz * max(np.median(np.diff(times)), 1e-9))))) if len(times) > 1 else 1
    for k in range(0, len(times), stride):
        plant.SetPositions(plant_context, q[k])
        query = scene_graph.get_query_output_port().Eval(sg_context)
        for a in part:
            for b in mold:
                d = query.ComputeSignedDistancePairClosestPoints(a, b).distance
                if d < 0.05 and d < best:
                    best, when = float(d), float(times[k])
    return best, when


def cell_clearance(scenario, times: np.ndarray, q: np.ndarray, rate_hz: float = 25.0) -> tuple[float, float, str]:
    """Smallest signed distance (m) between the robot (arm, gripper, part) and the cell (table,
    mold, glass) over a logged run, when, and which pair; (inf, nan, "") if never within 10 cm.

    The part and the mold it starts in are left out (`mold_clearance` scores them). A value
    <= 0 means contact.
    """
    from rtcohand_drake.cell.clearance import CellClearance

    clearance = CellClearance(scenario.cell, ignore=(("workpiece", "mold"),))
    best, when, which = float("inf"), float("nan"), ""
    if len(times) == 0:
        return best, when, which
    stride = max(1, int(round(1.0 / (rate_hz * max(np.median(np.diff(times)), 1e-9))))) if len(times) > 1 else 1
    for k in range(0, len(times), stride):
        d, pair = clearance.min_distance(q[k])
        if d < best:
            best, when, which = d, float(times[k]), pair
    return best, when, which


def score_run_log(log, scenario) -> tuple[float, float]:
    """Fills a run log's task results: faces inspected, completion, and mold contact.

    Sets `completed`, `faces_inspected`, `completion_time`, the extra attributes
    `mold_touched` and `mold_min_clearance_m`, and a `mold_contact` event when
    the part touched the walls; `cell_touched`, `cell_min_clearance_m` and a
    `cell_contact` event for the arm, gripper or part touching the table, mold
    or glass. Returns (closest distance to the mold walls, its time).
    """
    from rtcohand_drake.cell.plant import eye_position

    result = measure_inspection(log.robot_time, log.robot_workpiece_pose, eye_position(scenario.cell))
    log.completed, log.faces_inspected, log.completion_time = (
        result.completed, result.faces_inspected, result.completion_time)
    clearance, clearance_t = mold_clearance(scenario, log.robot_time, log.robot_q)
    log.extra_attrs.update(mold_touched=bool(clearance <= 0.0), mold_min_clearance_m=clearance)
    if clearance <= 0.0:
        log.add_event(clearance_t, "mold_contact", f"the workpiece touched the mold ({clearance * 1e3:.1f} mm)")
    cell, cell_t, pair = cell_clearance(scenario, log.robot_time, log.robot_q)
    log.extra_attrs.update(cell_touched=bool(cell <= 0.0), cell_min_clearance_m=cell)
    if cell <= 0.0:
        log.add_event(cell_t, "cell_contact", f"{pair} touched ({cell * 1e3:.1f} mm)")
    log.events.sort(key=lambda e: e.time)
    return clearance, clearance_t


def joint_excess(scenario, q: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """Largest excursion beyond the joint position limits (rad) and speed limits (rad/s); <= 0: within."""
    from rtcohand_drake.cell.plant import make_control_plant

    plant, _ = make_control_plant(scenario.cell)
    lo, hi = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    vmax = plant.GetVelocityUpperLimits()
    with np.errstate(invalid="ignore"):
        over_q = np.nanmax(np.maximum(q - hi, lo - q)) if len(q) else -np.inf
        over_v = np.nanmax(np.abs(v) - vmax) if len(v) else -np.inf
    return float(over_q), float(over_v)


def limits_exceeded(scenario, log, tolerance: float = 0.02) -> list[str]:
    """The limits a run log went beyond: the workpiece's peak linear and angular speed over the
    safety layer's limits (by more than `tolerance` of them), joint positions or speeds over the
    arm's; empty when within every one."""
    from rtcohand_drake.diagram import peak_speeds

    v_peak, w_peak = peak_speeds(log.robot_time, log.robot_workpiece_pose)
    over_q, over_v = joint_excess(scenario, log.robot_q, log.robot_v)
    hit = []
    if v_peak > scenario.safety.max_linear_speed_m_s * (1.0 + tolerance):
        hit.append(f"workpiece speed {v_peak:.3f} m/s")
    if w_peak > scenario.safety.max_angular_speed_rad_s * (1.0 + tolerance):
        hit.append(f"workpiece turn rate {w_peak:.3f} rad/s")
    if over_q > 0:
        hit.append(f"joint position {over_q:.3f} rad over")
    if over_v > 0:
        hit.append(f"joint speed {over_v:.3f} rad/s over")
    return hit
