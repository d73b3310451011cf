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

import numpy as np
import yaml

from rtcohand_drake.errors import InputError

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


class ScenarioError(InputError):
    """A scenario file that cannot be used; the message names file and problem."""


@dc.dataclass
class Pose:
    """A rigid transform: translation (m) and roll-pitch-yaw (degrees)."""

    xyz: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])
    rpy_deg: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])

    def to_rigid_transform(self):
        from pydrake.math import RigidTransform, RollPitchYaw

        return RigidTransform(RollPitchYaw(np.deg2rad(self.rpy_deg)), np.asarray(self.xyz, float))


@dc.dataclass
class Box:
    """An axis-aligned box in the world frame (m)."""

    min_xyz: list[float] = dc.field(default_factory=lambda: [-1.0, -1.0, 0.0])
    max_xyz: list[float] = dc.field(default_factory=lambda: [1.0, 1.0, 1.0])

    def contains(self, p) -> bool:
        p = np.asarray(p, float)
        return bool(np.all(p >= self.min_xyz) and np.all(p <= self.max_xyz))


@dc.dataclass
class Cell:
    """Where things stand, all in the world frame (origin: robot base on the table top)."""

    # Table top at z = 0; the table model's frame is on its top surface.
    table: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 0.15, 0.0]))
    # Mold frame: centre of the cavity floor (the mold's floor slab is 0.03 m thick).
    mold: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.45, -0.12, 0.03]))
    # Safety glass panel: bottom centre of the panel.
    safety_glass: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 0.52, 0.0]))
    # The inspector model's frame: on the floor below the eyes, x to the inspector's
    # right, y forward. Its `eye` frame (1.6 m up) is the eye point of the inspection measure.
    inspector: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 1.0, -0.74], rpy_deg=[0, 0, 180]))
    # The user frame U (contracts §6) in the world: X to the inspector's right, Y away
    # from the inspector toward the robot, Z up.
    user_frame: Pose = dc.field(default_factory=lambda: Pose(xyz=[0.25, 1.0, 0.86], rpy_deg=[0, 0, 180]))


@dc.dataclass
class Robot:
    # Arm joint angles at start (rad): the workpiece rests in the mold.
    q0_rad: list[float] = dc.field(default_factory=lambda: [0.0] * 7)
    # Joint-space PD gains of the simulated arm's position-velocity servo.
    kp_nm_per_rad: list[float] = dc.field(default_factory=lambda: [2000.0] * 4 + [500.0] * 3)
    kd_nm_s_per_rad: list[float] = dc.field(default_factory=lambda: [80.0] * 4 + [20.0] * 3)


@dc.dataclass
class DiffIk:
    """Differential inverse kinematics limits and gains."""

    # Fraction of the actuators' speed limits (80 deg/s large, 70 deg/s small) the solver may use.
    joint_velocity_fraction: float = 0.5
    joint_acceleration_rad_s2: float = 4.0
    # Keep this far inside the limited joints' position limits (MoveIt Servo's default margin).
    joint_position_margin_rad: float = 0.1
    # Continuous joints have no limit; the solver uses +-this to stay finite.
    continuous_joint_range_rad: float = 4 * math.pi
    # Cartesian speed limits on the workpiece centre (ISO 10218 reduced speed: 0.25 m/s).
    max_linear_speed_m_s: float = 0.25
    max_angular_speed_rad_s: float = 1.0
    joint_centering_gain: float = 0.5
    # Below this ratio of achieved to commanded twist the controller reports that it cannot follow.
    follow_ratio_threshold: float = 0.9
    # Clearance from the cell (table, mold, glass) for the arm, gripper and part: a pair
    # closer than cell_clearance_within_m may shrink at most at (d - margin) / approach time,
    # and not at all inside min_cell_clearance_m (rtcohand_drake.clearance). 0 switches it off.
    min_cell_clearance_m: float = 0.02
    cell_clearance_within_m: float = 0.10
    clearance_approach_time_s: float = 0.2


@dc.dataclass
class TwistSegment:
    """A constant commanded twist (user frame) held for a duration."""

    duration_s: float = 1.0
    twist: list[float] = dc.field(default_factory=lambda: [0.0] * 6)


@dc.dataclass
class Policy:
    """The CCHP policy system."""

    # Policy update rate (Hz); the paper's deployment runs at 10 Hz.
    rate_hz: float = 10.0
    # Exported TorchScript policy: a path, or a file name inside models/.
    model: str = "cchp_default.pt"
    # The twist output is r + w (mean - r), r the context read (attention . the user's own
    # labelled twists): 1 = the module's mean (the paper's CCHP), 0 = the read alone
    # (rtcohand_drake.policy_system).
    correction_weight: float = 1.0


@dc.dataclass
class CommandFilter:
    """The moving-average/downsampler between the policy and the safety supervisor."""

    # "paper": a command every command_period_s = mean of the last `window` predictions
    # (the paper's deployment: 2 Hz, 10 predictions). "responsive": a command at every
    # policy update = mean of the last `responsive_window` predictions, rate-limited.
    mode: str = "paper"
    window: int = 10
    command_period_s: float = 0.5
    responsive_window: int = 3
    # Per-axis clamp on the filtered twist [vx vy vz wx wy wz] (m/s, rad/s).
    clamp: list[float] = dc.field(default_factory=lambda: [0.15, 0.15, 0.15, 0.8, 0.8, 0.8])
    # Responsive mode's limit on how fast the command may change (m/s^2, rad/s^2).
    max_linear_accel_m_s2: float = 0.5
    max_angular_accel_rad_s2: float = 3.0


@dc.dataclass
class Safety:
    """The safety supervisor between the filter and the differential IK."""

    # Period of the supervisor's update (s).
    period_s: float = 0.02
    # Speed limits on the workpiece centre: ISO 10218 reduced speed 0.25 m/s.
    max_linear_speed_m_s: float = 0.25
    max_angular_speed_rad_s: float = 1.0
    # Operator's sensitivity scale on the requested twist (Meshcat slider range).
    sensitivity_default: float = 1.0
    sensitivity_min: float = 0.25
    sensitivity_max: float = 2.0
    # A pause brings the workpiece to rest over this time (s).
    pause_ramp_s: float = 0.5
    # A gesture older than this (s), or flagged invalid, trips the watchdog.
    stale_after_s: float = 0.3
    # So does a hand-part velocity above this (m/s or rad/s): no hand moves that fast, so it
    # is a tracking error (a fast hand moves at about 2-5 m/s, a wrist turns at up to ~15 rad/s).
    max_plausible_feature: float = 25.0
    # Minimum distance from the workpiece centre to the inspector's eye point (m).
    min_inspector_distance_m: float = 0.55
    # Look-ahead for the workspace and inspector-zone checks (s).
    lookahead_s: float = 0.1
    # Limit on how fast the output command may change (m/s^2, rad/s^2).
    max_linear_accel_m_s2: float = 1.0
    max_angular_accel_rad_s2: float = 6.0
    # Mold exit corridor: while the workpiece centre is over the cavity (its opening
    # plus this margin, m) and less than this height above the cavity floor (m), only
    # motion along the mold's axis passes, so the hot part leaves the mold without
    # touching its walls whatever the gesture asks. Default: the upright part (0.05 m
    # half height) clears the 0.04 m walls at 0.09 m, plus 1 cm. 0 switches it off.
    mold_exit_height_m: float = 0.10
    # Above that, up to this height, turns are still removed over the cavity: a turning
    # part sweeps its corners (0.094 m from its centre) below the centre, and must not
    # swing one into the walls (0.04 m high): 0.04 + 0.094 + 1 cm. 0: turns free above
    # the exit height.
    mold_turn_height_m: float = 0.145
    mold_exit_margin_m: float = 0.02
    # ... and below this height of the workpiece centre over the cavity floor (m) it may
    # not move down (the upright part rests at 0.052 m: python -m rtcohand_drake.initial_pose).
    mold_seat_height_m: float = 0.055


@dc.dataclass
class Scenario:
    name: str = "unnamed"
    # MultibodyPlant discrete time step (s).
    plant_time_step_s: float = 0.01
    # Period of the differential IK controller (s).
    control_period_s: float = 0.02
    # Rate at which the run log samples the robot (Hz); contracts §2 ask for >= 50.
    log_rate_hz: float = 50.0
    duration_s: float = 60.0
    cell: Cell = dc.field(default_factory=Cell)
    robot: Robot = dc.field(default_factory=Robot)
    diff_ik: DiffIk = dc.field(default_factory=DiffIk)
    # Where the workpiece centre may go (world frame).
    workspace: Box = dc.field(default_factory=Box)
    policy: Policy = dc.field(default_factory=Policy)
    command_filter: CommandFilter = dc.field(default_factory=CommandFilter)
    safety: Safety = dc.field(default_factory=Safety)
    # A scripted twist sequence, for runs without a gesture pipeline.
    scripted_motion: list[TwistSegment] = dc.field(default_factory=list)


# Fixed lengths of list fields, checked on load.
_LENGTHS = {"xyz": 3, "rpy_deg": 3, "min_xyz": 3, "max_xyz": 3,
            "q0_rad": 7, "kp_nm_per_rad": 7, "kd_nm_s_per_rad": 7, "twist": 6, "clamp": 6}


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
    need(s.log_rate_hz >= 50, "log_rate_hz must be >= 50 (contracts: robot log at least 50 Hz)")
    need(s.duration_s > 0, "duration_s must be > 0")
    need(0 < s.diff_ik.joint_velocity_fraction <= 1, "diff_ik.joint_velocity_fraction must be in (0, 1]")
    need(s.diff_ik.max_linear_speed_m_s > 0, "diff_ik.max_linear_speed_m_s must be > 0")
    need(s.diff_ik.max_angular_speed_rad_s > 0, "diff_ik.max_angular_speed_rad_s must be > 0")
    need(s.diff_ik.joint_acceleration_rad_s2 > 0, "diff_ik.joint_acceleration_rad_s2 must be > 0")
    need(all(a < b for a, b in zip(s.workspace.min_xyz, s.workspace.max_xyz)),
         "workspace: min_xyz must be below max_xyz on every axis")
    need(0 < s.policy.rate_hz <= 100, "policy.rate_hz must be in (0, 100]")
    need(0.0 <= s.policy.correction_weight <= 1.0,
         f"policy.correction_weight must be in [0, 1], got {s.policy.correction_weight}")
    d = s.diff_ik
    need(d.min_cell_clearance_m >= 0 and d.cell_clearance_within_m > d.min_cell_clearance_m
         and d.clearance_approach_time_s > 0,
         "diff_ik: need min_cell_clearance_m >= 0, cell_clearance_within_m > it, clearance_approach_time_s > 0")
    f = s.command_filter
    need(f.mode in ("paper", "responsive"), f"command_filter.mode must be 'paper' or 'responsive', got {f.mode!r}")
    need(f.window >= 1 and f.responsive_window >= 1, "command_filter windows must be >= 1")
    need(f.command_period_s > 0, "command_filter.command_period_s must be > 0")
    need(all(c > 0 for c in f.clamp), "command_filter.clamp entries must be > 0")
    need(f.max_linear_accel_m_s2 > 0 and f.max_angular_accel_rad_s2 > 0,
         "command_filter acceleration limits must be > 0")
    sa = s.safety
    need(sa.period_s > 0, "safety.period_s must be > 0")
    need(0 < sa.max_linear_speed_m_s <= 0.25,
         "safety.max_linear_speed_m_s must be in (0, 0.25] (ISO 10218 reduced speed)")
    need(sa.max_angular_speed_rad_s > 0, "safety.max_angular_speed_rad_s must be > 0")
    need(0 < sa.sensitivity_min <= sa.sensitivity_default <= sa.sensitivity_max,
         "safety: need 0 < sensitivity_min <= sensitivity_default <= sensitivity_max")
    need(sa.max_plausible_feature > 0, "safety.max_plausible_feature must be > 0")
    need(sa.pause_ramp_s > 0 and sa.stale_after_s > 0 and sa.lookahead_s >= 0,
         "safety: pause_ramp_s and stale_after_s must be > 0, lookahead_s >= 0")
    need(sa.max_linear_accel_m_s2 > 0 and sa.max_angular_accel_rad_s2 > 0,
         "safety acceleration limits must be > 0")
    need(min(sa.mold_exit_height_m, sa.mold_turn_height_m, sa.mold_exit_margin_m, sa.mold_seat_height_m) >= 0,
         "safety mold corridor heights and margin must be >= 0")
    for i, seg in enumerate(s.scripted_motion):
        need(seg.duration_s > 0, f"scripted_motion[{i}].duration_s must be > 0")


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
        node = {}
    _check_against_schema(node, Scenario, "", source)
    try:
        scenario = yaml_load_typed(schema=Scenario, data=text)
    except Exception as err:  # the schema check above catches nearly everything first
        raise ScenarioError(f"{source}: {err}") from None
    if scenario.name == "unnamed":
        scenario.name = path.stem
    _check_values(scenario, source)
    return scenario
