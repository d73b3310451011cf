"""`RunOverlay`: what Meshcat shows beside the cell during a run.

- the hand skeleton of the current gesture, drawn in front of the inspector
  (in the user frame, so a hand moving to the inspector's right moves right);
- the commanded twist as two arrows from the workpiece centre: linear velocity
  (blue, 1 m drawn per 1 m/s x `linear_scale`) and angular velocity (orange);
- a status lamp above the inspector: green running, amber paused, red watchdog.

Input ports: keypoints (63), twist_command (6), safety_status (3), workpiece.pose (7).
Drawing happens in a periodic publish event; the lamp's colour and the hand's
joints are also recorded into Meshcat's animation.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Rgba, Sphere
from pydrake.math import RigidTransform
from pydrake.systems.framework import EventStatus, LeafSystem

from rtcohand_drake.systems.safety.supervisor import Mode
from rtcohand_drake.interfaces import KEYPOINTS, SAFETY_STATUS, TWIST_COMMAND, WORKPIECE_POSE

# Bones of the 21-point hand skeleton (wrist 0; thumb 1-4; index 5-8; middle 9-12; ring 13-16; pinky 17-20).
BONES = [(0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (5, 9), (9, 10), (10, 11), (11, 12),
         (9, 13), (13, 14), (14, 15), (15, 16), (13, 17), (0, 17), (17, 18), (18, 19), (19, 20)]
LAMP = {Mode.RUNNING: Rgba(0.1, 0.8, 0.2, 1.0), Mode.PAUSED: Rgba(1.0, 0.7, 0.0, 1.0),
        Mode.WATCHDOG: Rgba(0.9, 0.1, 0.1, 1.0)}
PREFIX = "overlay"


class RunOverlay(LeafSystem):
    def __init__(self, meshcat, X_WU, period_s: float = 0.05,
                 hand_anchor_U=(0.35, 0.25, -0.35), linear_scale: float = 2.0, angular_scale: float = 0.3):
        super().__init__()
        self._meshcat = meshcat
        self._X_WU = X_WU  # the user frame U in the world (RigidTransform)
        self._anchor_U = np.asarray(hand_anchor_U, float)
        self._hand_offset = None  # set from the first skeleton seen, so the hand sits at the anchor
        self._lin_scale, self._ang_scale = linear_scale, angular_scale
        self._keypoints = self.DeclareVectorInputPort(KEYPOINTS, 63)
        self._twist = self.DeclareVectorInputPort(TWIST_COMMAND, 6)
        self._status = self.DeclareVectorInputPort(SAFETY_STATUS, 3)
        self._pose = self.DeclareVectorInputPort(WORKPIECE_POSE, 7)
        for i in range(21):
            meshcat.SetObject(f"{PREFIX}/hand/joint{i}", Sphere(0.008 if i else 0.012), Rgba(0.95, 0.75, 0.6, 1))
        eye = self._X_WU.translation()
        meshcat.SetObject(f"{PREFIX}/status_lamp", Sphere(0.04), LAMP[Mode.RUNNING])
        meshcat.SetTransform(f"{PREFIX}/status_lamp", RigidTransform(eye + [0.0, 0.0, 0.35]))
        self._mode = Mode.RUNNING
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
        if np.all(np.isfinite(pose)) and np.all(np.isfinite(twist)):
            R = self._X_WU.rotation().matrix()
            c = pose[:3]
            for name, vec, scale, rgba in (("linear", R @ twist[:3], self._lin_scale, Rgba(0.1, 0.3, 1.0, 1)),
                                           ("angular", R @ twist[3:], self._ang_scale, Rgba(1.0, 0.5, 0.0, 1))):
                tip = c + scale * vec
                mc.SetLine(f"{PREFIX}/twist/{name}", np.stack([c, tip]).T, 4.0, rgba)

        mode = Mode(int(round(self._status.Eval(context)[0])))
        if mode != self._mode:
            self._mode = mode
            mc.SetObject(f"{PREFIX}/status_lamp", Sphere(0.04), LAMP[mode])
        return EventStatus.Succeeded()
