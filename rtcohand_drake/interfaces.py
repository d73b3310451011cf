"""Port names and sizes of every box of the run diagram, in one place.

The diagram builder, the stations and the tests use these constants, so a
port is renamed here or nowhere. Units and timing are in each system's
docstring; the public file formats are in `docs/interfaces.md`.

    gesture source -> CchpPolicy -> MovingAverageDownsampler -> SafetySupervisor
        -> TwistToJointVelocity -> station (simulated Gen3 or Kortex arm)

Monogram names: a twist is [vx vy vz wx wy wz] in the user frame U, motion
dimensions always in the order Tx, Ty, Tz, Rx, Ry, Rz.
"""

# --- sizes ---------------------------------------------------------------------

# The feature size is defined beside the features (hand_features, free of Drake, so the
# learning code uses the same constant).
from rtcohand_drake.data.hand_features import FEATURE_DIM  # noqa: F401  (36) hand-part velocities

NUM_JOINTS = 7  # Gen3 7-DoF: Actuator1 ... Actuator7
TWIST_DIM = 6  # [vx vy vz wx wy wz]
POSE_DIM = 7  # [x y z qw qx qy qz]
KEYPOINTS_DIM = 63  # 21 hand keypoints x 3, row-major
SCALAR_DIM = 1  # a one-entry port: a count, a factor or a mode

# --- the station (simulated and Kortex: exactly the same port set) -------------

VELOCITY_COMMAND = "gen3.velocity_command"  # in (7) joint velocities, rad/s
POSITION_MEASURED = "gen3.position_measured"  # out (7) joint angles, rad
VELOCITY_ESTIMATED = "gen3.velocity_estimated"  # out (7) joint velocities, rad/s
POSITION_COMMANDED = "gen3.position_commanded"  # out (7) servo's position target, rad
WORKPIECE_POSE = "workpiece.pose"  # out (7) workpiece centre in the world
QUERY_OBJECT = "query_object"  # out (abstract) SceneGraph queries

STATION_INPUTS = {VELOCITY_COMMAND: NUM_JOINTS}
# None: an abstract-valued port.
STATION_OUTPUTS = {POSITION_MEASURED: NUM_JOINTS, VELOCITY_ESTIMATED: NUM_JOINTS,
                   POSITION_COMMANDED: NUM_JOINTS, WORKPIECE_POSE: POSE_DIM, QUERY_OBJECT: None}

# --- gesture sources (every source has the three outputs) -----------------------

GESTURE_FEATURES = "gesture_features"  # (36) hand-part velocities at the policy rate
GESTURE_STATUS = "gesture_status"  # (2) [valid (0/1), time of the frame (s)]
KEYPOINTS = "keypoints"  # (63) current hand skeleton, user frame, NaN when lost
INTENDED_TWIST = "intended_twist"  # (6) the simulated person's intended twist (optional)
GESTURE_STATUS_DIM = 2

GESTURE_SOURCE_OUTPUTS = {GESTURE_FEATURES: FEATURE_DIM, GESTURE_STATUS: GESTURE_STATUS_DIM,
                          KEYPOINTS: KEYPOINTS_DIM}

# --- the policy -------------------------------------------------------------------

RESUME_COUNT = "resume_count"  # (1) in: resumes so far (a change resamples z)
POLICY_MEAN = "policy_mean"  # (6) out: the predicted twist
POLICY_STD = "policy_std"  # (6) out
ATTENTION = "attention"  # (K) out: attention over the context steps
READ_VARIANCE = "read_variance"  # (1) out: the read's predictive variance factor v >= 1 (1: like the context)

# --- command filter, operator panel, supervisor, differential IK -----------------

TWIST_REQUEST = "twist_request"  # (6) filtered twist, to the supervisor
OPERATOR = "operator"  # (2) [pause (0/1), sensitivity factor], from the operator panel
OPERATOR_DIM = 2
HAND_SIGN = "hand_sign"  # (3) [toggled (0/1), openness, toggles], from the pause hand sign
HAND_SIGN_DIM = 3
TWIST_COMMAND = "twist_command"  # (6) the supervisor's command, to the differential IK
SAFETY_STATUS = "safety_status"  # (3) [mode, resume_count, interventions]
SAFETY_STATUS_DIM = 3
SPEED_SCALE = "speed_scale"  # (1) the supervisor's confidence scale on the request, in [floor, 1]
FOLLOW_STATUS = "follow_status"  # (2) the differential IK's follow status
FACES_INSPECTED = "faces_inspected"  # (6) 1 for each workpiece face that has counted as seen
