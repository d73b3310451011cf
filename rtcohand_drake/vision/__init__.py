"""Seeing the person: hand landmarks, the camera's calibration, ArUco markers.

No pydrake here. `landmarker` runs MediaPipe's hand landmarker from the model
bundle shipped in `models/hand_tracking/`; `hand_pose` turns its landmarks
into 21 keypoints in metres in the user frame; `calibration` holds the
camera's intrinsics and its pose in the user frame; `capture` feeds frames
from a video file (in simulated time) or a live camera (in its own thread);
`drawn_hand` draws a hand at known keypoints, the offline test image;
`aruco` tracks an ArUco-marked object (the recorder's `--labels aruco`), and
`calibrate` is the one-time camera-pose command from a marker.
"""
