"""Scenario files: YAML loaded into typed dataclasses.

A scenario holds every number a user could want to change for a run: the cell
layout, the arm's initial joint angles, time steps, limits and the workspace.
`load_scenario("inspection")` loads the built-in file
`rtcohand_drake/scenarios/inspection.yaml`; any other argument is a path.

Files are parsed with Drake's `yaml_load_typed` after a check of every key
against the schema below, so a typo (`max_linear_speed_ms`) or a wrong type is
one line naming the file, the key path and the problem (`ScenarioError`).

Units: metres, radians, seconds unless a field's name says otherwise
(`rpy_deg`, `..._deg_s`).
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads real field types.
import dataclasses as dc
import math
import typing
from pathlib import Path

import yaml

from rtcohand_drake.cell.layout import Box, Cell, Robot
from rtcohand_drake.errors import InputError
from rtcohand_drake.systems.diff_ik import DiffIk
from rtcohand_drake.systems.hand_sign_config import HandSign
from rtcohand_drake.systems.moving_average_downsampler import CommandFilter
from rtcohand_drake.systems.policy import Policy
from rtcohand_drake.systems.safety.config import Safety
from rtcohand_drake.systems.scripted_twist import TwistSegment
from rtcohand_drake.vision.config import Camera
from rtcohand_drake.vision.hand_pose_filter import DEPTH_CUES, SMOOTHERS

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


class ScenarioError(InputError):
    """A scenario file that cannot be used; the message names file and problem."""


@dc.dataclass
class Scenario:
    name: str = "unnamed"
    # MultibodyPlant discrete time step (s).
    plant_time_step_s: float = 0.01
    # Period of the differential IK controller (s).
    control_period_s: float = 0.02
    # Rate at which the run log samples the robot (Hz); the run log needs >= 50 (docs/interfaces.md).
    log_rate_hz: float = 50.0
    # The longest a run lasts when the command gives no --duration (s, simulated) ...
    duration_s: float = 180.0
    # ... which ends it this long after all six faces have been inspected, when stop_when_done.
    stop_when_done: bool = True
    done_hold_s: float = 3.0
    cell: Cell = dc.field(default_factory=Cell)
    robot: Robot = dc.field(default_factory=Robot)
    diff_ik: DiffIk = dc.field(default_factory=DiffIk)
    # Where the workpiece centre may go (world frame).
    workspace: Box = dc.field(default_factory=Box)
    policy: Policy = dc.field(default_factory=Policy)
    command_filter: CommandFilter = dc.field(default_factory=CommandFilter)
    safety: Safety = dc.field(default_factory=Safety)
    # The camera gesture source's hand tracker (--gesture-source camera).
    camera: Camera = dc.field(default_factory=Camera)
    # The pause hand sign (a closed fist held still).
    hand_sign: HandSign = dc.field(default_factory=HandSign)
    # A scripted twist sequence, for runs without a gesture pipeline.
    scripted_motion: list[TwistSegment] = dc.field(default_factory=list)


# Fixed lengths of list fields, checked on load.
_LENGTHS = {"xyz": 3, "rpy_deg": 3, "min_xyz": 3, "max_xyz": 3,
            "q0_rad": 7, "kp_nm_per_rad": 7, "kd_nm_s_per_rad": 7, "twist": 6, "clamp": 6, "deadband": 6, "mold_exit_half_xy_m": 2}


def builtin_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """A built-in name (`inspection`) or a path to a YAML file."""
    text = str(name_or_path)
    if (SCENARIO_DIR / f"{text}.yaml").is_file() and not Path(text).suffix:
        return SCENARIO_DIR / f"{text}.yaml"
    path = Path(text)
    if path.is_file():
        return path
    raise ScenarioError(
        f"{text}: no such scenario file or built-in scenario "
        f"(built-in: {', '.join(builtin_scenarios()) or 'none'})")


def _check_against_schema(node, schema, where: str, source: str) -> None:
    """Finds unknown keys and wrong shapes with their full key path."""
    if dc.is_dataclass(schema):
        if not isinstance(node, dict):
            raise ScenarioError(f"{source}: {where or 'top level'}: expected a mapping, got {type(node).__name__}")
        hints = typing.get_type_hints(schema)
        known = {f.name for f in dc.fields(schema)}
        for key, value in node.items():
            path = f"{where}.{key}" if where else str(key)
            if key not in known:
                raise ScenarioError(f"{source}: {path}: unknown key (known here: {', '.join(sorted(known))})")
            _check_against_schema(value, hints[key], path, source)
        return
    origin = typing.get_origin(schema)
    if origin is list:
        if not isinstance(node, list):
            raise ScenarioError(f"{source}: {where}: expected a list, got {node!r}")
        (item_type,) = typing.get_args(schema)
        leaf = where.rsplit(".", 1)[-1]
        if leaf in _LENGTHS and len(node) != _LENGTHS[leaf]:
            raise ScenarioError(f"{source}: {where}: expected {_LENGTHS[leaf]} numbers, got {len(node)}")
        for i, item in enumerate(node):
            _check_against_schema(item, item_type, f"{where}[{i}]", source)
        return
    if schema is float:
        if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(node):
            raise ScenarioError(f"{source}: {where}: expected a finite number, got {node!r}")
    elif schema is int:
        if isinstance(node, bool) or not isinstance(node, int):
            raise ScenarioError(f"{source}: {where}: expected a whole number, got {node!r}")
    elif schema is str and not isinstance(node, str):
        raise ScenarioError(f"{source}: {where}: expected text, got {node!r}")


def _check_values(s: Scenario, source: str) -> None:
    def need(cond: bool, what: str):
        if not cond:
            raise ScenarioError(f"{source}: {what}")

    need(s.plant_time_step_s > 0, "plant_time_step_s must be > 0")
    need(s.control_period_s >= s.plant_time_step_s, "control_period_s must be >= plant_time_step_s")
    need(s.log_rate_hz >= 50, "log_rate_hz must be >= 50 (the run log samples the robot at >= 50 Hz)")
    need(s.duration_s > 0, "duration_s must be > 0")
    need(s.done_hold_s >= 0, "done_hold_s must be >= 0")
    need(0 < s.diff_ik.joint_velocity_fraction <= 1, "diff_ik.joint_velocity_fraction must be in (0, 1]")
    need(s.diff_ik.max_linear_speed_m_s > 0, "diff_ik.max_linear_speed_m_s must be > 0")
    need(s.diff_ik.max_angular_speed_rad_s > 0, "diff_ik.max_angular_speed_rad_s must be > 0")
    need(s.diff_ik.joint_acceleration_rad_s2 > 0, "diff_ik.joint_acceleration_rad_s2 must be > 0")
    need(all(a < b for a, b in zip(s.workspace.min_xyz, s.workspace.max_xyz)),
         "workspace: min_xyz must be below max_xyz on every axis")
    need(0 < s.policy.rate_hz <= 100, "policy.rate_hz must be in (0, 100]")
    need(0.0 <= s.policy.correction_weight <= 1.0,
         f"policy.correction_weight must be in [0, 1], got {s.policy.correction_weight}")
    need(math.isfinite(s.policy.output_gain) and 1.0 <= s.policy.output_gain <= 5.0,
         f"policy.output_gain must be in [1, 5], got {s.policy.output_gain}")
    r = s.robot
    need(all(math.isfinite(v) and v >= 0 for v in list(r.kp_nm_per_rad) + list(r.kd_nm_s_per_rad)),
         "robot.kp_nm_per_rad and robot.kd_nm_s_per_rad entries must be >= 0")
    d = s.diff_ik
    need(d.min_cell_clearance_m >= 0 and d.cell_clearance_within_m > d.min_cell_clearance_m
         and d.clearance_approach_time_s > 0,
         "diff_ik: need min_cell_clearance_m >= 0, cell_clearance_within_m > it, clearance_approach_time_s > 0")
    need(d.tracking_weight > 0, "diff_ik.tracking_weight must be > 0")
    need(d.joint_position_influence_rad > d.joint_position_margin_rad,
         "diff_ik.joint_position_influence_rad must be > joint_position_margin_rad")
    f = s.command_filter
    need(f.mode in ("paper", "responsive"), f"command_filter.mode must be 'paper' or 'responsive', got {f.mode!r}")
    need(f.window >= 1 and f.responsive_window >= 1, "command_filter windows must be >= 1")
    need(f.command_period_s > 0, "command_filter.command_period_s must be > 0")
    need(all(c > 0 for c in f.clamp), "command_filter.clamp entries must be > 0")
    need(all(math.isfinite(d) and 0 <= 2 * d < c for d, c in zip(f.deadband, f.clamp)),
         "command_filter.deadband entries must be >= 0 and less than half the clamp's")
    need(f.max_linear_accel_m_s2 > 0 and f.max_angular_accel_rad_s2 > 0,
         "command_filter acceleration limits must be > 0")
    sa = s.safety
    need(sa.period_s > 0, "safety.period_s must be > 0")
    need(0 < sa.max_linear_speed_m_s <= 0.25,
         "safety.max_linear_speed_m_s must be in (0, 0.25] (ISO 10218 reduced speed)")
    need(sa.max_angular_speed_rad_s > 0, "safety.max_angular_speed_rad_s must be > 0")
    need(0 < sa.sensitivity_min <= sa.sensitivity_default <= sa.sensitivity_max,
         "safety: need 0 < sensitivity_min <= sensitivity_default <= sensitivity_max")
    need(sa.max_plausible_feature > 0 and sa.max_plausible_angular_feature > 0,
         "safety.max_plausible_feature and safety.max_plausible_angular_feature must be > 0")
    need(sa.pause_ramp_s > 0 and sa.stale_after_s > 0 and sa.lookahead_s >= 0,
         "safety: pause_ramp_s and stale_after_s must be > 0, lookahead_s >= 0")
    need(sa.max_linear_accel_m_s2 > 0 and sa.max_angular_accel_rad_s2 > 0,
         "safety acceleration limits must be > 0")
    need(min(sa.mold_exit_height_m, sa.mold_turn_height_m, sa.mold_exit_margin_m, sa.mold_seat_height_m,
             *sa.mold_exit_half_xy_m) >= 0,
         "safety mold corridor heights and margin must be >= 0")
    c = s.camera
    need(c.num_hands >= 1, "camera.num_hands must be >= 1")
    need(all(0.0 <= v <= 1.0 for v in (c.min_detection_confidence, c.min_presence_confidence,
                                       c.min_tracking_confidence)), "camera confidence thresholds must be in [0, 1]")
    need(c.hand in ("right", "left", "largest"), f"camera.hand must be right, left or largest, got {c.hand!r}")
    need(0 <= c.blur_sigma_px <= 5, "camera.blur_sigma_px must be in [0, 5]")
    pf = c.pose_filter
    need(pf.depth_cue in DEPTH_CUES, f"camera.pose_filter.depth_cue must be one of {', '.join(DEPTH_CUES)}, "
                                     f"got {pf.depth_cue!r}")
    need(pf.smoother in SMOOTHERS, f"camera.pose_filter.smoother must be one of {', '.join(SMOOTHERS)}, "
                                   f"got {pf.smoother!r}")
    need(pf.palm_size_m >= 0 and pf.palm_size_from_first_s >= 0,
         "camera.pose_filter: palm_size_m and palm_size_from_first_s must be >= 0")
    need(min(pf.min_cutoff_hz, pf.derivative_cutoff_hz, pf.kalman_accel_m_s2, pf.kalman_depth_noise_m,
             pf.max_depth_speed_m_s, pf.reset_after_s) > 0 and pf.beta_hz_per_m_s >= 0 and pf.jump_floor_m >= 0,
         "camera.pose_filter: cutoffs, Kalman noises, max_depth_speed_m_s and reset_after_s must be > 0, "
         "beta_hz_per_m_s and jump_floor_m >= 0")
    h = s.hand_sign
    need(h.hold_s > 0 and h.period_s > 0, "hand_sign.hold_s and hand_sign.period_s must be > 0")
    need(0 < h.fist_below < h.open_above, "hand_sign: need 0 < fist_below < open_above")
    need(h.max_drift_m > 0, "hand_sign.max_drift_m must be > 0")
    need(0 < h.thumb_up_within_deg and h.thumb_hysteresis_deg >= 0
         and h.thumb_up_within_deg + h.thumb_hysteresis_deg < 90,
         "hand_sign: need 0 < thumb_up_within_deg, thumb_hysteresis_deg >= 0, their sum < 90")
    need(0 <= h.axis_from_up_min_deg < 180, "hand_sign: need 0 <= axis_from_up_min_deg < 180")
    for i, seg in enumerate(s.scripted_motion):
        need(seg.duration_s > 0, f"scripted_motion[{i}].duration_s must be > 0")


def _check_duplicate_keys(text: str, source: str) -> None:
    """A key given twice in one mapping: YAML keeps the last silently, so one of the two settings would be
    ignored without a word."""
    def walk(node) -> None:
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    if key.value in seen:
                        raise ScenarioError(f"{source}: line {key.start_mark.line + 1}: {key.value!r} is given twice")
                    seen.add(key.value)
                walk(value)
        elif isinstance(node, yaml.SequenceNode):
            for item in node.value:
                walk(item)

    walk(yaml.compose(text))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Loads and validates a scenario; raises ScenarioError (one line) on bad input."""
    from pydrake.common.yaml import yaml_load_typed

    path = resolve_scenario_path(name_or_path)
    source = str(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ScenarioError(f"{source}: cannot read: {err}") from None
    try:
        node = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(err, "problem", None) or "malformed YAML"
        raise ScenarioError(f"{source}: {at}malformed YAML ({problem})") from None
    if node is None:
        raise ScenarioError(f"{source}: the file is empty (give a mapping of settings, as "
                            "rtcohand_drake/scenarios/inspection.yaml; an empty mapping {} means every default)")
    _check_duplicate_keys(text, source)
    _check_against_schema(node, Scenario, "", source)
    try:
        scenario = yaml_load_typed(schema=Scenario, data=text)
    except Exception as err:  # the schema check above catches nearly everything first
        raise ScenarioError(f"{source}: {err}") from None
    if scenario.name == "unnamed":
        scenario.name = path.stem
    _check_values(scenario, source)
    return scenario
