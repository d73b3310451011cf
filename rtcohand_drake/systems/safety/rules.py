"""The safety rules: each one pure function and one flag, and the table the run log reads.

A zone rule limits the command by where the workpiece is. It takes the
command as a user-frame twist plus its linear part in the world, and returns
both, with whether it acted:

    rule(twist_U, v_W, p_W, zones) -> (twist_U, v_W, acted)

`RULES` lists every intervention the supervisor reports, in the order the zone
rules apply. Each entry has its flag (a bit of the supervisor's
`safety_status[2]`) and the run-log event it becomes (docs/interfaces.md). To
add a zone rule: write its function here, add a flag to `Intervention` and a
row to `RULES` (and its numbers to `Safety` in `config.py`). The supervisor and
the run log pick it up from the table.
"""

from __future__ import annotations

import dataclasses as dc
import enum
from typing import Callable

import numpy as np

from rtcohand_drake.cell.geometry import all_close, vector_norm
from rtcohand_drake.systems.safety.config import Safety


class Mode(enum.IntEnum):
    RUNNING = 0
    PAUSED = 1
    WATCHDOG = 2


class Intervention(enum.IntFlag):
    NONE = 0
    SPEED_CLAMP = 1
    WORKSPACE = 2
    INSPECTOR_ZONE = 4
    WATCHDOG = 8
    PAUSED = 16
    NON_FINITE = 32
    MOLD_EXIT = 64
    LOW_CONFIDENCE = 128


@dc.dataclass(frozen=True)
class Zones:
    """The geometry the zone rules need, fixed for a run (world frame W, user frame U)."""

    config: Safety
    R_WU: np.ndarray  # (3, 3)
    box_lo: np.ndarray  # workspace box, (3,)
    box_hi: np.ndarray
    eye_W: np.ndarray  # the inspector's eye point
    X_mold_W: object | None = None  # RigidTransform world -> mold frame, or None (no mold rule)
    mold_axis_W: np.ndarray | None = None  # the mold's +z in the world


def remove_outward_component(v_W: np.ndarray, normal_W: np.ndarray) -> np.ndarray:
    """v with its component along `normal_W` (unit, pointing out of the allowed set) removed if positive."""
    along = float(v_W @ normal_W)
    return v_W - along * normal_W if along > 0 else v_W


def plausible_features(x: np.ndarray, config: Safety) -> bool:
    """Finite, and no hand part moving faster than a hand can: each part's linear velocity (the first
    three of its six values) within `max_plausible_feature` m/s, its angular velocity (the last three)
    within `max_plausible_angular_feature` rad/s."""
    parts = np.abs(np.asarray(x, float)).reshape(-1, 6)  # the hand's parts, as hand_features lays them out
    return bool(np.isfinite(parts).all() and parts[:, :3].max(initial=0.0) <= config.max_plausible_feature
                and parts[:, 3:].max(initial=0.0) <= config.max_plausible_angular_feature)


def mold_exit_position(p_W: np.ndarray, zones: Zones) -> np.ndarray | None:
    """The workpiece centre in the mold frame while it is over the cavity and below the turn height, else None."""
    cfg = zones.config
    if zones.X_mold_W is None or cfg.mold_exit_height_m <= 0.0:
        return None
    p = zones.X_mold_W.multiply(p_W)
    half_x, half_y = cfg.mold_exit_half_xy_m
    margin = cfg.mold_exit_margin_m
    top = max(cfg.mold_exit_height_m, cfg.mold_turn_height_m)
    inside = abs(p[0]) <= half_x + margin and abs(p[1]) <= half_y + margin and p[2] < top
    return p if inside else None


def mold_exit(twist_U, v_W, p_W, zones: Zones):
    """In the mold's exit corridor only motion along the mold's axis passes: no turn, no
    sideways move. Above it, up to the turn height, only the turns are removed."""
    p_mold = mold_exit_position(p_W, zones)
    if p_mold is None:
        return twist_U, v_W, False
    cfg = zones.config
    if p_mold[2] >= cfg.mold_exit_height_m:  # clear of the walls, but a turn could swing a corner into them
        out = np.concatenate([twist_U[:3], np.zeros(3)])
        return out, v_W, bool(np.max(np.abs(twist_U[3:])) > 1e-9)
    axis_W = zones.mold_axis_W
    along = float(v_W @ axis_W)
    if along < 0.0 and p_mold[2] <= cfg.mold_seat_height_m:
        along = 0.0  # seated: pressing the part into the cavity floor only tilts it
    out = np.zeros(6)
    out[:3] = zones.R_WU.T @ (axis_W * along)
    return out, zones.R_WU @ out[:3], bool(np.max(np.abs(out - twist_U)) > 1e-9)


def workspace_box(twist_U, v_W, p_W, zones: Zones):
    """Removes velocity that would carry the workpiece centre (looked ahead) out of the workspace box."""
    ahead = (p_W + v_W * zones.config.lookahead_s).tolist()
    p, lo, hi = np.asarray(p_W).tolist(), zones.box_lo.tolist(), zones.box_hi.tolist()
    acted = False
    for axis in range(3):
        if ahead[axis] > hi[axis] or p[axis] > hi[axis]:
            outward = 1.0
        elif ahead[axis] < lo[axis] or p[axis] < lo[axis]:
            outward = -1.0
        else:
            continue
        normal = np.zeros(3)
        normal[axis] = outward
        v_new = remove_outward_component(v_W, normal)
        if not all_close(v_new, v_W):
            acted = True
        v_W = v_new
    return twist_U, v_W, acted


def inspector_zone(twist_U, v_W, p_W, zones: Zones):
    """Removes motion toward the inspector's eye once the part (looked ahead) is closer than the minimum."""
    to_part = p_W - zones.eye_W
    distance = vector_norm(to_part)
    ahead = p_W + v_W * zones.config.lookahead_s
    if vector_norm(ahead - zones.eye_W) < zones.config.min_inspector_distance_m and distance > 1e-9:
        v_new = remove_outward_component(v_W, -to_part / distance)
        return twist_U, v_new, not all_close(v_new, v_W)
    return twist_U, v_W, False


ZoneRule = Callable[[np.ndarray, np.ndarray, np.ndarray, Zones], tuple[np.ndarray, np.ndarray, bool]]


@dc.dataclass(frozen=True)
class Rule:
    flag: Intervention
    event: str  # the run-log event kind while it acts
    limit: ZoneRule | None = None  # None: applied by the supervisor itself (speed clamp, non-finite input)


# Zone rules apply in this order (the mold corridor first: it decides which directions pass at all).
RULES = (
    Rule(Intervention.SPEED_CLAMP, "clamp"),
    Rule(Intervention.MOLD_EXIT, "mold_exit", mold_exit),
    Rule(Intervention.WORKSPACE, "workspace", workspace_box),
    Rule(Intervention.INSPECTOR_ZONE, "inspector_zone", inspector_zone),
    Rule(Intervention.NON_FINITE, "fault"),
    Rule(Intervention.LOW_CONFIDENCE, "low_confidence"),
)


def confidence_scale(variance: float, config: Safety) -> float:
    """The speed scale for the read's variance factor v: 1 up to the full-speed variance, then down
    linearly to the floor at the floor variance; the floor for a non-finite v; 1 when switched off."""
    if not config.confidence_scaling:
        return 1.0
    if not np.isfinite(variance):
        return float(config.confidence_floor)
    span = max(config.confidence_floor_variance - config.confidence_full_variance, 1e-9)
    share = min(max((variance - config.confidence_full_variance) / span, 0.0), 1.0)
    return 1.0 - (1.0 - config.confidence_floor) * share


def limit_to_zones(twist_U: np.ndarray, p_W: np.ndarray, zones: Zones) -> tuple[np.ndarray, Intervention]:
    """Applies every zone rule of `RULES` in order; returns the limited twist and the flags that acted."""
    acted = Intervention.NONE
    v_W = zones.R_WU @ twist_U[:3]
    for rule in RULES:
        if rule.limit is not None:
            twist_U, v_W, did = rule.limit(twist_U, v_W, p_W, zones)
            if did:
                acted |= rule.flag
    out = np.array(twist_U, float)
    out[:3] = zones.R_WU.T @ v_W
    return out, acted
