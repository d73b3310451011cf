"""Does the part follow the gestures? Wrong-way and drift shares of a run log.

Both read the run log's `/gesture/intended` (the twist the simulated or
recorded person means, at the policy rate, held until the next sample) and
the workpiece's velocity from `/robot/workpiece_pose`, differenced between
successive samples and expressed in the user frame U (the centre's linear
velocity, the angular velocity about the centre).

- **Gesture time**: the samples where the intended twist is not zero. Its
  command is the axis where the intended twist is largest as a share of a
  full command (`FULL_COMMAND`: 0.12 m/s, 0.6 rad/s), with that sign.
- `wrong_way_share`: of the gesture time, the share in which the part moves
  against the command: its velocity along the command's axis, times the
  command's sign, below -`share` (20 %) of a full command.
- **Rest time**: the samples outside gesture time that are at least
  `settle_s` (0.5 s) past the end of the last gesture (the run's start counts
  as one), up to the next gesture.
- `drift_share`: of the rest time, the share in which the part moves faster
  than `share` of a full command on any axis.

A share with no time to take it of is None.

`stuck_motion`, for a run that did not finish: over its last `last_s` (60 s),
the command the person gestured most, the share of those seconds' samples
spent on it, and the read's gain along it: sum(output x label) / sum(label^2)
on its axis over those samples, the policy's output held at each sample
(1: the label's size; 0: the part is not asked to move at all).
"""

from __future__ import annotations

import numpy as np

from rtcohand_drake.cell.geometry import quaternion_to_matrix, rotation_vector

FULL_COMMAND = np.array([0.12, 0.12, 0.12, 0.6, 0.6, 0.6])  # m/s, rad/s: the recorded labels' size


def workpiece_twist_U(times: np.ndarray, poses_W: np.ndarray, R_WU: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(midpoint times (K-1,), twists (K-1, 6) in U) from poses [x y z qw qx qy qz] in the world."""
    times = np.asarray(times, float)
    poses_W = np.asarray(poses_W, float)
    if len(times) < 2:
        return np.zeros(0), np.zeros((0, 6))
    dt = np.diff(times)
    v_W = np.diff(poses_W[:, :3], axis=0) / dt[:, None]
    R = quaternion_to_matrix(poses_W[:, 3:7])
    w_W = np.array([rotation_vector(R[k + 1] @ R[k].T) for k in range(len(dt))]) / dt[:, None]
    R_UW = np.asarray(R_WU, float).T
    return 0.5 * (times[1:] + times[:-1]), np.hstack([v_W @ R_UW.T, w_W @ R_UW.T])


def following_shares(times: np.ndarray, twists_U: np.ndarray, intent_times: np.ndarray, intended: np.ndarray,
                     share: float = 0.2, settle_s: float = 0.5) -> tuple[float | None, float | None]:
    """(wrong_way_share, drift_share) of the part's twists at `times`, against the intended twist
    sampled at `intent_times` (module doc)."""
    times, twists_U = np.asarray(times, float), np.asarray(twists_U, float)
    intent_times, intended = np.asarray(intent_times, float), np.asarray(intended, float)
    if len(times) == 0 or len(intent_times) == 0:
        return None, None
    k = np.searchsorted(intent_times, times + 1e-9, side="right") - 1  # the intent held at each time
    a = np.where(k[:, None] >= 0, intended[np.clip(k, 0, None)], 0.0)
    gesture = np.any(a != 0.0, axis=1)
    relative = np.abs(a) / FULL_COMMAND
    axis = np.argmax(relative, axis=1)
    sign = np.sign(a[np.arange(len(a)), axis])
    along = sign * twists_U[np.arange(len(a)), axis] / FULL_COMMAND[axis]
    wrong = gesture & (along < -share)
    rest = np.zeros(len(times), bool)
    end, in_gesture = times[0], False  # the run's start counts as the end of a gesture
    for i in range(len(times)):
        if gesture[i]:
            in_gesture = True
            continue
        if in_gesture:
            end, in_gesture = times[i], False
        rest[i] = times[i] - end >= settle_s - 1e-9
    drift = rest & np.any(np.abs(twists_U) > share * FULL_COMMAND, axis=1)
    wrong_way = float(wrong.sum() / gesture.sum()) if gesture.any() else None
    drifting = float(drift.sum() / rest.sum()) if rest.any() else None
    return wrong_way, drifting


def run_log_following_shares(log, R_WU: np.ndarray) -> tuple[float | None, float | None]:
    """`following_shares` of a run log (`run_log.RunLog`) with the user frame's rotation R_WU."""
    times, twists = workpiece_twist_U(log.robot_time, log.robot_workpiece_pose, R_WU)
    return following_shares(times, twists, log.gesture_time, log.gesture_intended)


AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
STUCK_WINDOW_S = 60.0


def stuck_motion(intent_times: np.ndarray, intended: np.ndarray, policy_times: np.ndarray,
                 policy_means: np.ndarray, last_s: float = STUCK_WINDOW_S) -> dict | None:
    """{"motion" ("Ty+"), "time_share", "gain"} of a run's last `last_s` seconds (module doc); None when the
    person gestured nothing then."""
    intent_times, intended = np.asarray(intent_times, float), np.asarray(intended, float)
    policy_times, policy_means = np.asarray(policy_times, float), np.asarray(policy_means, float)
    if len(intent_times) == 0 or len(policy_times) == 0:
        return None
    window = intent_times > intent_times[-1] - last_s
    a = intended[window]
    k = np.searchsorted(policy_times, intent_times[window] + 1e-9, side="right") - 1  # the output held
    out = np.where(k[:, None] >= 0, policy_means[np.clip(k, 0, None)], 0.0)
    gesture = np.any(a != 0.0, axis=1)
    if not gesture.any():
        return None
    axis = np.argmax(np.abs(a) / FULL_COMMAND, axis=1)
    sign = np.sign(a[np.arange(len(a)), axis])
    names = np.array([f"{AXES[d]}{'+' if s > 0 else '-'}" for d, s in zip(axis, sign)])
    motions, counts = np.unique(names[gesture], return_counts=True)
    motion = str(motions[np.argmax(counts)])
    on = gesture & (names == motion)
    d = AXES.index(motion[:2])
    gain = float((out[on, d] * a[on, d]).sum() / (a[on, d] ** 2).sum())
    return {"motion": motion, "time_share": float(on.sum() / len(a)), "gain": gain}
