"""`InspectionMonitor`: which of the workpiece's six faces the inspector has seen, live.

It applies the task's own rule (`rtcohand_drake.analysis.inspection`: a face
counts once its outward normal has pointed within 35 degrees of the line to
the inspector's eye for 0.5 s), sampled every `period_s` (the run log's
robot rate, so it counts exactly as the run's score does). The run command
ends a run a short hold after all six are seen; the Meshcat overlay lights
each face's mark once it counts.

Input ports
  workpiece.pose   (7) [x y z qw qx qy qz], world
Output ports
  faces_inspected  (6) 1 for each face (order of `cell.faces.FACES`) that has counted, else 0
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from rtcohand_drake.analysis.inspection import advance_holds, face_angles_deg, MAX_ANGLE_DEG
from rtcohand_drake.cell.faces import FACES
from rtcohand_drake.interfaces import FACES_INSPECTED, POSE_DIM, WORKPIECE_POSE


class InspectionMonitor(LeafSystem):
    def __init__(self, eye_W, period_s: float):
        super().__init__()
        self._eye = np.asarray(eye_W, float)
        n = len(FACES)
        self._pose = self.DeclareVectorInputPort(WORKPIECE_POSE, POSE_DIM)
        # [view start (n), hold completed at (n)], NaN when not.
        self._holds = self.DeclareDiscreteState(np.full(2 * n, np.nan))
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareVectorOutputPort(FACES_INSPECTED, n, self._calc_faces, prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        n = len(FACES)
        holds = context.get_discrete_state(self._holds).get_value()
        pose = self._pose.Eval(context)
        visible = np.zeros(n, bool)
        if np.isfinite(pose).all():
            visible = face_angles_deg(pose, self._eye)[0] <= MAX_ANGLE_DEG
        start, done = advance_holds(holds[:n], holds[n:], context.get_time(), visible)
        discrete_state.set_value(self._holds, np.concatenate([start, done]))

    def inspected_at(self, context) -> np.ndarray:
        """(6) time each face's hold completed, NaN where it has not."""
        return context.get_discrete_state(self._holds).get_value()[len(FACES):].copy()

    def _calc_faces(self, context, output):
        output.SetFromVector(np.isfinite(self.inspected_at(context)).astype(float))


def until_done(monitor: InspectionMonitor, hold_s: float):
    """A simulator monitor (`Simulator.set_monitor`) that ends the run `hold_s` after the last face counted."""
    from pydrake.systems.framework import EventStatus

    def check(root):
        # Called after every simulator step: read the state in place, no copy.
        done_at = monitor.GetMyContextFromRoot(root).get_discrete_state(monitor._holds).get_value()[len(FACES):]
        if np.isfinite(done_at).all() and root.get_time() >= done_at.max() + hold_s - 1e-9:
            return EventStatus.ReachedTermination(monitor, "all six faces inspected")
        return EventStatus.DidNothing()

    return check
