"""`KinematicWorkpiece`: a stand-in for the whole station that moves the part exactly as commanded.

No arm, no dynamics: the workpiece pose integrates the commanded twist (user
frame), for tests and notebooks of the simulated person without the plant.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from rtcohand_drake.cell.geometry import matrix_to_quaternion, quaternion_to_matrix
from rtcohand_drake.data.population import rotation_matrices
from rtcohand_drake.interfaces import TWIST_DIM, WORKPIECE_POSE


class KinematicWorkpiece(LeafSystem):
    """A stand-in for the robot: the workpiece follows a twist (user frame) exactly.

    Input `twist` (6, U); output `workpiece.pose` (7, world), integrated every `period_s`.
    """

    def __init__(self, X_WU, initial_pose_W, period_s: float = 0.02):
        super().__init__()
        self._R_WU = X_WU.rotation().matrix()
        self._dt = period_s
        self._twist = self.DeclareVectorInputPort("twist", TWIST_DIM)
        self._pose = self.DeclareDiscreteState(np.asarray(initial_pose_W, float))
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        self.DeclareStateOutputPort(WORKPIECE_POSE, self._pose)

    def _update(self, context, discrete_state):
        pose = context.get_discrete_state(self._pose).get_value()
        twist = np.asarray(self._twist.Eval(context), float)
        p = pose[:3] + self._R_WU @ twist[:3] * self._dt
        R = rotation_matrices((self._R_WU @ twist[3:] * self._dt)[None])[0] @ quaternion_to_matrix(pose[None, 3:])[0]
        discrete_state.set_value(self._pose, np.concatenate([p, matrix_to_quaternion(R)]))
