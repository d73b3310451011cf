"""The safety supervisor's settings: the `safety` key of a scenario (units in the names)."""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc


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
    # So does a hand part's linear velocity above this (m/s): no hand moves that fast, so it is a
    # tracking error (a fast hand moves at about 2-5 m/s).
    max_plausible_feature: float = 25.0
    # ... or a hand part's angular velocity above this (rad/s). A part's angular velocity is the
    # rotation between two poses over their time apart (hand_features: |theta| < pi), so a finger's
    # frame that turns half a turn between two frames (the finger lined up with the palm's across
    # axis, which the frame is built from) reads up to pi / dt: 31 rad/s at 10 Hz, 63 rad/s for
    # frames 0.05 s apart, while the hand itself is fine. 4 of the 268 policy steps of real camera
    # footage (10 clips through MediaPipe) and 1.0-1.5 % of recorded people's (SHREC'17) reach
    # 25 rad/s this way, with no linear velocity above 4 m/s (experiments/implausible_features.py).
    # The limit sits above pi / dt for frames at least 0.032 s apart; a wrist turns at up to ~15 rad/s.
    max_plausible_angular_feature: float = 100.0
    # Confidence scaling: the request is scaled by the policy's confidence, from the read's
    # predictive variance factor v = 1 + phi^T A phi (port read_variance): full speed up to
    # v = confidence_full_variance, falling linearly to confidence_floor at
    # confidence_floor_variance and beyond. Chosen on the development population (seed 0):
    # a person's own held-out gestures give v = 1.01-1.09 (10th-99th percentile), another
    # person's gestures read with this person's clips 1.09 (median), 1.29 (90th), 1.78 (99th).
    confidence_scaling: bool = True
    confidence_full_variance: float = 1.1
    confidence_floor_variance: float = 1.6
    confidence_floor: float = 0.3
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
    # Half extents (m, mold frame x and y) of the area over the cavity where the corridor
    # applies, before the margin. It must cover the cavity of models/cell/mold.sdf (a test
    # checks): 0.083 along x; 0.058 along y covers the 0.033 half width with 25 mm to spare.
    mold_exit_half_xy_m: list[float] = dc.field(default_factory=lambda: [0.083, 0.058])
    # ... and below this height of the workpiece centre over the cavity floor (m) it may
    # not move down (the upright part rests at 0.052 m: python -m rtcohand_drake.initial_pose).
    mold_seat_height_m: float = 0.055
