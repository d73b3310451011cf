"""The pause hand sign's settings: the `hand_sign` key of a scenario (units in the names)."""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc


@dc.dataclass
class HandSign:
    """A closed fist held still toggles the pause (`rtcohand_drake.systems.hand_sign`)."""

    # Off: the sign is not wired in, the operator panel alone pauses.
    enabled: bool = True
    # How long the fist must be held (s) before the pause toggles.
    hold_s: float = 0.5
    # Openness: the mean fingertip distance from the wrist over the mean knuckle (MCP) distance
    # from the wrist. An open hand reads about 1.9, a relaxed one 1.5-1.8, a fist under 1.0. The
    # hand counts as a fist below `fist_below`, and as open again only above `open_above` (the
    # hysteresis); after a toggle the hand must open before the next one can start.
    fist_below: float = 1.05
    open_above: float = 1.35
    # While the fist is held the hand must stay this still (m/s, the wrist's speed): a fist
    # moving through a gesture is not the sign.
    max_wrist_speed_m_s: float = 0.15
    # Update period (s).
    period_s: float = 0.05
