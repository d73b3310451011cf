"""`RunOverlay`: what Meshcat shows beside the cell during a run.

- the hand skeleton of the current gesture, drawn in front of the inspector
  (in the user frame, so a hand moving to the inspector's right moves right);
- the commanded twist as two arrows with heads, starting just outside the
  part (so the part never hides them): linear velocity in blue (0.1 m of arrow
  per 0.05 m/s) and angular velocity in orange (0.1 m per 0.2 rad/s), each
  about its own axis through the part's centre;
- the policy's uncertainty as a translucent ball at each arrow's tip, of
  radius one standard deviation on the arrow's scale (where the tip could be);
- a board of six face marks above the glass, one per face in its plate's
  colour: dim until that face counts as inspected, then lit;
- a status lamp at the board's end: green running, amber paused, pale blue
  "hand away" (the watchdog holding the part still while no hand is in view:
  a normal moment between strokes), red for a fault (non-finite input, a
  stale camera feed with a hand in it).

Input ports: keypoints (63), twist_command (6), safety_status (3),
workpiece.pose (7), and optionally gesture_status (2), policy_std (6) and
faces_inspected (6). Drawing happens in a periodic publish event; every
transform and visibility change is also recorded into Meshcat's animation,
so the page replays the run after it ends.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Box, Cylinder, MeshcatCone, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import EventStatus, LeafSystem

from rtcohand_drake.cell.faces import COLOUR_RGBA, FACES, face_key
from rtcohand_drake.interfaces import (FACES_INSPECTED, GESTURE_STATUS, GESTURE_STATUS_DIM, KEYPOINTS, KEYPOINTS_DIM,
                                       POLICY_STD, POSE_DIM, SAFETY_STATUS, SAFETY_STATUS_DIM, TWIST_COMMAND,
                                       TWIST_DIM, WORKPIECE_POSE)
from rtcohand_drake.systems.safety.rules import Intervention
from rtcohand_drake.systems.safety.supervisor import Mode

# Bones of the 21-point hand skeleton (wrist 0; thumb 1-4; index 5-8; middle 9-12; ring 13-16; pinky 17-20).
BONES = [(0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (5, 9), (9, 10), (10, 11), (11, 12),
         (9, 13), (13, 14), (14, 15), (15, 16), (13, 17), (0, 17), (17, 18), (18, 19), (19, 20)]
# The lamp's states, each its own object (shown one at a time).
LAMP = {"running": Rgba(0.1, 0.8, 0.2, 1.0), "paused": Rgba(1.0, 0.7, 0.0, 1.0),
        "hand_away": Rgba(0.55, 0.75, 1.0, 1.0), "fault": Rgba(0.9, 0.1, 0.1, 1.0)}
ARROWS = {"linear": Rgba(0.1, 0.3, 1.0, 1.0), "angular": Rgba(1.0, 0.5, 0.0, 1.0)}
PREFIX = "overlay"
# Arrows start this far from the part's centre: beyond its corners (0.094 m away).
ARROW_START_M = 0.1
SHAFT_RADIUS_M = 0.008
HEAD_LENGTH_M = 0.04
HEAD_RADIUS_M = 0.02
MIN_ARROW_M = 0.004  # shorter arrows are hidden
# Centre of the face board (world frame): above the top edge of the safety glass (models/cell).
BOARD_W = (0.25, 0.52, 1.08)


def lamp_state(mode: int, interventions: int, gesture_valid: float) -> str:
    """Which lamp to show: a watchdog stop with no hand in view is "hand away", any other is a fault."""
    if mode == Mode.PAUSED:
        return "paused"
    if mode == Mode.WATCHDOG:
        if interventions & Intervention.NON_FINITE or gesture_valid >= 0.5:
            return "fault"  # non-finite input, or a hand in a feed that has gone stale
        return "hand_away"
    return "running"


def _frame_along(z_axis: np.ndarray) -> RotationMatrix:
    """A rotation whose z axis is the unit vector `z_axis`."""
    z = z_axis / np.linalg.norm(z_axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return RotationMatrix(np.column_stack([x, np.cross(z, x), z]))


class RunOverlay(LeafSystem):
    def __init__(self, meshcat, X_WU, period_s: float = 0.05, hand_anchor_U=(0.35, 0.25, -0.35),
                 linear_scale: float = 2.0, angular_scale: float = 0.5, board_W=None):
        super().__init__()
        self._meshcat = meshcat
        self._X_WU = X_WU  # the user frame U in the world (RigidTransform)
        self._anchor_U = np.asarray(hand_anchor_U, float)
        self._hand_offset = None  # set from the first skeleton seen, so the hand sits at the anchor
        self._scales = {"linear": linear_scale, "angular": angular_scale}
        self._keypoints = self.DeclareVectorInputPort(KEYPOINTS, KEYPOINTS_DIM)
        self._twist = self.DeclareVectorInputPort(TWIST_COMMAND, TWIST_DIM)
        self._status = self.DeclareVectorInputPort(SAFETY_STATUS, SAFETY_STATUS_DIM)
        self._pose = self.DeclareVectorInputPort(WORKPIECE_POSE, POSE_DIM)
        self._gesture = self.DeclareVectorInputPort(GESTURE_STATUS, GESTURE_STATUS_DIM)
        self._std = self.DeclareVectorInputPort(POLICY_STD, TWIST_DIM)
        self._faces = self.DeclareVectorInputPort(FACES_INSPECTED, len(FACES))
        for i in range(21):
            meshcat.SetObject(f"{PREFIX}/hand/joint{i}", Sphere(0.008 if i else 0.012), Rgba(0.95, 0.75, 0.6, 1))
        for name, rgba in ARROWS.items():
            # A unit-length shaft, stretched to the arrow's length by its scale property.
            meshcat.SetObject(f"{PREFIX}/twist/{name}/shaft", Cylinder(SHAFT_RADIUS_M, 1.0), rgba)
            meshcat.SetObject(f"{PREFIX}/twist/{name}/head", MeshcatCone(HEAD_LENGTH_M, HEAD_RADIUS_M, HEAD_RADIUS_M),
                              rgba)
            meshcat.SetObject(f"{PREFIX}/twist/{name}/uncertainty", Sphere(1.0),
                              Rgba(rgba.r(), rgba.g(), rgba.b(), 0.15))
            meshcat.SetProperty(f"{PREFIX}/twist/{name}", "visible", False)
        # The face board and the lamp sit in a row along the glass's top edge, in the inspector's view.
        board = np.asarray(board_W if board_W is not None else BOARD_W, float)
        right_W = self._X_WU.rotation().matrix()[:, 0]
        lamp_at = RigidTransform(board + 3.7 * 0.07 * right_W)
        for state, rgba in LAMP.items():
            meshcat.SetObject(f"{PREFIX}/status_lamp/{state}", Sphere(0.04), rgba)
            meshcat.SetTransform(f"{PREFIX}/status_lamp/{state}", lamp_at)
            meshcat.SetProperty(f"{PREFIX}/status_lamp/{state}", "visible", state == "running")
        self._lamp = "running"
        # The face board: six marks, in the inspector's left-to-right order.
        for k, (face, _, colour) in enumerate(FACES):
            at = RigidTransform(board + (k - 2.5) * 0.07 * right_W)
            r, g, b, _ = COLOUR_RGBA[colour]
            for lit, rgba in (("dim", Rgba(r, g, b, 0.2)), ("lit", Rgba(r, g, b, 1.0))):
                path = f"{PREFIX}/faces/{face_key(face)}/{lit}"
                meshcat.SetObject(path, Box(0.05, 0.05, 0.05) if lit == "lit" else Box(0.045, 0.045, 0.045), rgba)
                meshcat.SetTransform(path, at)
                meshcat.SetProperty(path, "visible", lit == "dim")
        self._lit = np.zeros(len(FACES), bool)
        self.DeclarePeriodicPublishEvent(period_s, 0.0, self._draw)

    def _draw(self, context) -> EventStatus:
        mc, t = self._meshcat, context.get_time()
        kp = np.asarray(self._keypoints.Eval(context), float).reshape(21, 3)
        seen = np.all(np.isfinite(kp))
        if seen:
            if self._hand_offset is None:
                self._hand_offset = self._anchor_U - kp.mean(axis=0)
            p_W = np.array([self._X_WU.multiply(p + self._hand_offset) for p in kp])
            for i, p in enumerate(p_W):
                mc.SetTransform(f"{PREFIX}/hand/joint{i}", RigidTransform(p), t)
            mc.SetLineSegments(f"{PREFIX}/hand/bones", p_W[[a for a, _ in BONES]].T, p_W[[b for _, b in BONES]].T,
                               2.0, Rgba(0.9, 0.6, 0.45, 1))
        mc.SetProperty(f"{PREFIX}/hand", "visible", bool(seen), t)

        pose = self._pose.Eval(context)
        twist = self._twist.Eval(context)
        std = self._std.Eval(context) if self._std.HasValue(context) else np.zeros(6)
        if np.all(np.isfinite(pose)) and np.all(np.isfinite(twist)):
            R = self._X_WU.rotation().matrix()
            for name, part in (("linear", slice(0, 3)), ("angular", slice(3, 6))):
                self._draw_arrow(name, pose[:3], R @ twist[part], self._scales[name],
                                 float(np.linalg.norm(std[part])) if np.all(np.isfinite(std)) else 0.0, t)

        mode, _, acted = self._status.Eval(context)
        valid = self._gesture.Eval(context)[0] if self._gesture.HasValue(context) else 1.0
        lamp = lamp_state(int(round(mode)), int(round(acted)), float(valid))
        if lamp != self._lamp:
            mc.SetProperty(f"{PREFIX}/status_lamp/{self._lamp}", "visible", False, t)
            mc.SetProperty(f"{PREFIX}/status_lamp/{lamp}", "visible", True, t)
            self._lamp = lamp

        if self._faces.HasValue(context):
            lit = np.asarray(self._faces.Eval(context)) >= 0.5
            for k in np.flatnonzero(lit != self._lit):
                key = face_key(FACES[k][0])
                mc.SetProperty(f"{PREFIX}/faces/{key}/lit", "visible", bool(lit[k]), t)
                mc.SetProperty(f"{PREFIX}/faces/{key}/dim", "visible", not lit[k], t)
            self._lit = lit
        return EventStatus.Succeeded()

    def _draw_arrow(self, name: str, centre_W: np.ndarray, vec_W: np.ndarray, scale: float, std: float,
                    t: float) -> None:
        mc, path = self._meshcat, f"{PREFIX}/twist/{name}"
        length = scale * float(np.linalg.norm(vec_W))
        if length < MIN_ARROW_M:
            mc.SetProperty(path, "visible", False, t)
            return
        u = vec_W / np.linalg.norm(vec_W)
        start = centre_W + ARROW_START_M * u
        shaft = max(length - HEAD_LENGTH_M, 1e-3)
        R = _frame_along(u)
        mc.SetTransform(f"{path}/shaft", RigidTransform(R, start + 0.5 * shaft * u), t)
        # Meshcat draws a cylinder along its object's own y axis (the frame above turns it onto z).
        mc.SetProperty(f"{path}/shaft/<object>", "scale", [1.0, shaft, 1.0], t)
        # The cone's apex is its origin and it opens along its z axis: apex at the tip, opening backward.
        tip = start + max(length, HEAD_LENGTH_M) * u
        mc.SetTransform(f"{path}/head", RigidTransform(_frame_along(-u), tip), t)
        radius = max(scale * std, 1e-3)
        mc.SetTransform(f"{path}/uncertainty", RigidTransform(tip), t)
        mc.SetProperty(f"{path}/uncertainty/<object>", "scale", [radius] * 3, t)
        mc.SetProperty(path, "visible", True, t)
