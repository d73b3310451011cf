"""The pause hand sign's settings: the `hand_sign` key of a scenario (units in the names)."""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc


@dc.dataclass
class HandSign:
    """A thumbs-up held still toggles the pause (`rtcohand_drake.systems.hand_sign`)."""

    # Off: the sign is not wired in, the operator panel alone pauses.
    enabled: bool = True
    # How long the sign must be held (s) before the pause toggles.
    hold_s: float = 0.5
    # Openness: the mean fingertip distance from the wrist over the mean knuckle (MCP) distance
    # from the wrist. An open hand reads about 1.9, a relaxed one 1.5-1.8, a fist under 1.0. The
    # fingers count as closed below `fist_below`, and as open again only above `open_above`.
    # MediaPipe reads a drawn fist at 1.1-1.2; the thumb test below is what sets the sign
    # apart from the fists people gesture with.
    fist_below: float = 1.3
    open_above: float = 1.55
    # The thumb (MCP to tip) must point within this angle of up (deg); once the sign is made it
    # ends only beyond this plus the hysteresis. The population's fists point it 70 deg or more
    # from up.
    thumb_up_within_deg: float = 35.0
    thumb_hysteresis_deg: float = 15.0
    # The hand's axis (wrist to the middle finger's knuckle) must be at least this far from up
    # (deg): a thumbs-up is made with the fist on its side, knuckles forward or across. A hand held
    # upright as it closes (recorded grabs, pinches and the ends of swipes) points its thumb up
    # too, its axis 20 deg from up (median). Once the sign is made it ends only below this minus
    # `thumb_hysteresis_deg`. Chosen on recorded development people (SHREC'17 subjects 2, 4, 8,
    # 10, 12, 14, 16, 20, 22, 26; experiments/pause_sign_scan.py): the sign toggled after 111 of
    # their 399 custom clips (49 of 408 whole-hand) without it, 2 (0) with 50 deg (docs/real_people.md,
    # the pause sign).
    axis_from_up_min_deg: float = 50.0
    # While the sign is held every point of the hand must stay within this distance (m) of where
    # it was when the hold began: a hand moving through a gesture is not the sign, the tracker's
    # jitter (about 1 cm) is.
    max_drift_m: float = 0.03
    # Update period (s): the policy's, the rate at which the gesture sources' skeletons change.
    period_s: float = 0.1
