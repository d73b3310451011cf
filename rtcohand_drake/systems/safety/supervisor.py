"""`SafetySupervisor`: the last software gate before the differential IK.

Every `period_s` it turns the filtered twist request into the twist command:

1. watchdog: a gesture flagged invalid, older than `stale_after_s`, with a
   non-finite or physically implausible feature (a hand part faster than
   `max_plausible_feature` m/s or `max_plausible_angular_feature` rad/s), or a
   non-finite request, sets the target to zero,
   and the command decays to zero within one command period (linearly, from
   where it was);
2. pause: the operator's pause brings the workpiece to rest over
   `pause_ramp_s` and holds it; resume counts up `resume_count` (the policy
   resamples its latent z and the filter forgets its history on a change);
3. sensitivity and confidence: the request is scaled by the operator's factor,
   clipped to [sensitivity_min, sensitivity_max], and by the policy's confidence
   (`rules.confidence_scale` of the read's variance factor: 1 for a gesture like
   the person's context, down to `confidence_floor` for one unlike all of it);
4. speed limits: |v| <= max_linear_speed_m_s and |w| <= max_angular_speed_rad_s
   (direction kept);
5. workspace box and inspector zone: the velocity component that would carry
   the workpiece centre (looked ahead by `lookahead_s`) out of the workspace
   box, or closer than `min_inspector_distance_m` to the inspector's eye, is
   removed;
6. the command changes no faster than the acceleration limits, except that
   watchdog and pause decelerations are always allowed at their own rate.

Input ports
  twist_request   (6) [vx vy vz wx wy wz], user frame (from the filter)
  gesture_status  (2) [valid (0/1), time of the gesture frame (s)]
  gesture_features (36) optional: the features the policy reads, checked for sanity
  workpiece.pose  (7) [x y z qw qx qy qz], world
  operator        (2) [pause (0/1), sensitivity factor]
  read_variance   (1) optional: the policy's read variance factor v (unconnected: full confidence)
Output ports
  twist_command   (6) user frame, to the differential IK
  safety_status   (3) [mode, resume_count, interventions]: mode 0 running,
                  1 paused, 2 watchdog; interventions is a bit set (1 speed
                  clamp, 2 workspace, 4 inspector zone, 8 watchdog, 16 paused,
                  32 non-finite request, 64 mold exit corridor, 128 slowed for low
                  confidence) of what acted at the last
                  update (the table `rules.RULES` names each).
  resume_count    (1) number of resumes so far
  speed_scale     (1) the confidence scale applied at the last update, in [confidence_floor, 1]
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.cell.geometry import all_close, vector_norm
from rtcohand_drake.systems.diff_ik import clamp_twist
from rtcohand_drake.cell.layout import Box
from rtcohand_drake.systems.safety.config import Safety
from rtcohand_drake.systems.safety.rules import Intervention, Mode, Zones, confidence_scale, limit_to_zones, plausible_features
from rtcohand_drake.interfaces import (FEATURE_DIM, GESTURE_FEATURES, GESTURE_STATUS, GESTURE_STATUS_DIM, OPERATOR,
                                       OPERATOR_DIM, POSE_DIM, READ_VARIANCE, RESUME_COUNT, SAFETY_STATUS,
                                       SAFETY_STATUS_DIM, SCALAR_DIM, SPEED_SCALE, TWIST_COMMAND, TWIST_DIM,
                                       TWIST_REQUEST, WORKPIECE_POSE)


class SafetySupervisor(LeafSystem):
    def __init__(self, config: Safety, workspace: Box, R_WU: np.ndarray, eye_W: np.ndarray,
                 command_period_s: float, X_W_mold=None):
        super().__init__()
        self._cfg = config
        # The mold's frame (origin: centre of the cavity floor, z up out of the cavity), or None.
        self.zones = Zones(
            config=config, R_WU=np.asarray(R_WU, float),
            box_lo=np.asarray(workspace.min_xyz, float), box_hi=np.asarray(workspace.max_xyz, float),
            eye_W=np.asarray(eye_W, float),
            X_mold_W=None if X_W_mold is None else X_W_mold.inverse(),
            mold_axis_W=None if X_W_mold is None else X_W_mold.rotation().matrix()[:, 2])
        self._dt = config.period_s
        # The watchdog brings the command to zero within one command period.
        self._watchdog_ramp_s = min(command_period_s, config.pause_ramp_s)
        self._request = self.DeclareVectorInputPort(TWIST_REQUEST, TWIST_DIM)
        self._gesture = self.DeclareVectorInputPort(GESTURE_STATUS, GESTURE_STATUS_DIM)
        self._features = self.DeclareVectorInputPort(GESTURE_FEATURES, FEATURE_DIM)
        self._pose = self.DeclareVectorInputPort(WORKPIECE_POSE, POSE_DIM)
        self._operator = self.DeclareVectorInputPort(OPERATOR, OPERATOR_DIM)
        self._variance = self.DeclareVectorInputPort(READ_VARIANCE, SCALAR_DIM)
        self._command = self.DeclareDiscreteState(np.zeros(6))
        # [mode, resume_count, interventions, paused_input_last, ramp_from_norm_v, ramp_from_norm_w]
        self._state = self.DeclareDiscreteState(np.zeros(6))
        self._scale = self.DeclareDiscreteState(np.ones(1))
        self.DeclarePeriodicDiscreteUpdateEvent(self._dt, 0.0, self._update)
        self.DeclareStateOutputPort(TWIST_COMMAND, self._command)
        self.DeclareVectorOutputPort(SAFETY_STATUS, SAFETY_STATUS_DIM, self._calc_status, prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort(RESUME_COUNT, SCALAR_DIM, self._calc_resume, prerequisites_of_calc={self.xd_ticket()})
        self.DeclareStateOutputPort(SPEED_SCALE, self._scale)

    def limit_to_zones(self, twist_U: np.ndarray, p_W: np.ndarray) -> tuple[np.ndarray, Intervention]:
        """The zone rules of `rules.RULES` (mold corridor, workspace box, inspector zone) on a command."""
        return limit_to_zones(twist_U, p_W, self.zones)

    def _accel_step(self) -> np.ndarray:
        return np.array([self._cfg.max_linear_accel_m_s2] * 3 + [self._cfg.max_angular_accel_rad_s2] * 3) * self._dt

    # --- the update ---------------------------------------------------------------

    def _update(self, context, discrete_state):
        cfg = self._cfg
        t = context.get_time()
        command = context.get_discrete_state(self._command).get_value().copy()
        mode, resumes, _, paused_last, ramp_v, ramp_w = context.get_discrete_state(self._state).get_value()
        acted = Intervention.NONE

        pause_in, sensitivity = self._operator.Eval(context)
        paused = bool(pause_in >= 0.5)
        if paused_last >= 0.5 and not paused:
            resumes += 1  # a resume: the policy resamples z
        valid, frame_time = self._gesture.Eval(context)
        request = np.asarray(self._request.Eval(context), float)
        if not np.isfinite(request).all():
            acted |= Intervention.NON_FINITE
        stale = (valid < 0.5) or not np.isfinite(frame_time) or (t - frame_time > cfg.stale_after_s) \
            or bool(acted & Intervention.NON_FINITE)
        if self._features.HasValue(context) and not plausible_features(self._features.Eval(context), cfg):
            stale = True
            acted |= Intervention.NON_FINITE

        confidence = 1.0
        if self._variance.HasValue(context):
            confidence = confidence_scale(float(self._variance.Eval(context)[0]), cfg)
            if confidence < 1.0:
                acted |= Intervention.LOW_CONFIDENCE
        if paused:
            new_mode, ramp_s = Mode.PAUSED, cfg.pause_ramp_s
            acted |= Intervention.PAUSED
        elif stale:
            new_mode, ramp_s = Mode.WATCHDOG, self._watchdog_ramp_s
            acted |= Intervention.WATCHDOG
        else:
            new_mode, ramp_s = Mode.RUNNING, None

        if ramp_s is not None:
            if mode == Mode.RUNNING:  # a ramp to zero starts here; a pause <-> watchdog switch keeps it
                ramp_v, ramp_w = vector_norm(command[:3]), vector_norm(command[3:])
            command = self._ramp_to_zero(command, ramp_v, ramp_w, ramp_s)
        else:
            s = min(max(float(sensitivity) if np.isfinite(sensitivity) else cfg.sensitivity_default,
                        cfg.sensitivity_min), cfg.sensitivity_max)
            target = s * confidence * request
            clamped = clamp_twist(target, cfg.max_linear_speed_m_s, cfg.max_angular_speed_rad_s)
            if not all_close(clamped, target):
                acted |= Intervention.SPEED_CLAMP
            step = self._accel_step()
            command = command + np.clip(clamped - command, -step, step)
        # The zone rules act on the command actually sent, whatever the mode.
        pose = self._pose.Eval(context)
        if np.isfinite(pose).all():
            command, zones = self.limit_to_zones(command, pose[:3])
            acted |= zones
        else:
            command[:] = 0.0
            acted |= Intervention.NON_FINITE
        command = clamp_twist(command, cfg.max_linear_speed_m_s, cfg.max_angular_speed_rad_s)
        discrete_state.set_value(self._command, command)
        discrete_state.set_value(self._scale, [confidence])
        discrete_state.set_value(self._state, np.array(
            [float(new_mode), resumes, float(int(acted)), 1.0 if paused else 0.0, ramp_v, ramp_w]))

    def _ramp_to_zero(self, command: np.ndarray, from_v: float, from_w: float, ramp_s: float) -> np.ndarray:
        """Shrinks v and w toward zero, each at the rate that ends the ramp in `ramp_s`."""
        out = command.copy()
        for part, start in ((slice(0, 3), from_v), (slice(3, 6), from_w)):
            norm = vector_norm(out[part])
            if norm <= 1e-12:
                out[part] = 0.0
                continue
            new_norm = max(0.0, norm - max(start, norm) * self._dt / ramp_s)
            out[part] *= new_norm / norm
        return out

    def _calc_status(self, context, output: BasicVector):
        mode, resumes, acted, *_ = context.get_discrete_state(self._state).get_value()
        output.SetFromVector([mode, resumes, acted])

    def _calc_resume(self, context, output: BasicVector):
        output.SetFromVector([context.get_discrete_state(self._state).get_value()[1]])
