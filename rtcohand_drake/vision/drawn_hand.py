"""A hand drawn with OpenCV at known keypoints: the offline test image for the hand tracker.

No photograph of a hand ships with any package this project uses, so the
tests and the latency benchmark draw one: shaded capsules for the bones and
a filled palm, in skin tones, over a textured background, at the image
points of a known 3D skeleton. MediaPipe finds such a hand, and the drawing's
keypoints are the ground truth its landmarks are checked against.

`open_hand_U(...)` is an open right hand held up, palm toward a camera in
front of the person, from the project's hand model
(`rtcohand_drake.data.population.hand_model`).
"""

from __future__ import annotations

import numpy as np

from rtcohand_drake.data.population.hand_model import hand_keypoints_local

# Bones, base to tip, per finger (thumb, index, middle, ring, pinky).
FINGERS = ((1, 2, 3, 4), (5, 6, 7, 8), (9, 10, 11, 12), (13, 14, 15, 16), (17, 18, 19, 20))
SKIN_BGR = np.array([140, 170, 215])  # a mid skin tone; shading darkens the rim

# The hand frame H of the hand model (palm down, fingers +Y, back of the hand +Z)
# turned into U for a hand held up, palm forward: fingers up, back toward the person.
R_UH_PALM_FORWARD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def open_hand_U(wrist_U=(0.0, 0.0, 0.0), R_UH: np.ndarray | None = None, scale: float = 1.0,
                curl: float = 0.0) -> np.ndarray:
    """Keypoints (21, 3), metres, user frame: a right hand, fingers curled by `curl` (0 flat .. 1 fist)."""
    local = hand_keypoints_local(np.full((1, 4), curl), np.zeros((1, 4)),
                                 np.deg2rad([[25.0, 25.0, 15.0, 10.0]]) * (1 + curl), scale)[0]
    R = R_UH_PALM_FORWARD if R_UH is None else np.asarray(R_UH, float)
    return (local - local[0]) @ R.T + np.asarray(wrist_U, float)


def background(width: int, height: int, seed: int = 0) -> np.ndarray:
    """A grey, lightly textured background (BGR, uint8), the same for a given seed."""
    import cv2

    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, 1.0, (height // 8 + 1, width // 8 + 1)).astype(np.float32)
    noise = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    ramp = np.linspace(-12.0, 12.0, width, dtype=np.float32)[None, :]
    grey = np.clip(90.0 + 5.0 * noise + ramp, 0, 255).astype(np.uint8)
    return cv2.merge([grey, grey, (grey * 0.95).astype(np.uint8)])


def _capsule(image, a, b, radius: float, colour) -> None:
    import cv2

    cv2.line(image, tuple(np.round(a).astype(int)), tuple(np.round(b).astype(int)),
             tuple(int(c) for c in colour), max(1, int(round(2 * radius))), cv2.LINE_AA)


def draw_hand(image: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Draws a hand with its 21 keypoints at `points_px` (21, 2) into `image` (BGR), in place."""
    import cv2

    p = np.asarray(points_px, float)
    palm_width = float(np.linalg.norm(p[5] - p[17]))
    finger_r = 0.16 * palm_width
    rim, mid, core = SKIN_BGR * 0.75, SKIN_BGR * 0.9, SKIN_BGR
    # The palm: the knuckles, the thumb's base and a wrist as wide as most of the palm.
    across = (p[17] - p[5]) / max(palm_width, 1e-9)
    wrist = [p[0] + 0.42 * palm_width * across, p[0] - 0.42 * palm_width * across]
    outline = np.array([*wrist, p[1], p[2], p[5], p[9], p[13], p[17]])
    # A forearm, out of the palm's far side: the palm detector expects a hand on an arm.
    elbow = p[0] + 2.0 * (p[0] - p[9])
    _capsule(image, p[0], elbow, 0.4 * palm_width, rim)
    _capsule(image, p[0], elbow, 0.34 * palm_width, mid)
    hull = cv2.convexHull(np.round(outline).astype(np.int32))
    cv2.fillConvexPoly(image, hull, tuple(int(c) for c in rim), cv2.LINE_AA)
    centre = hull.reshape(-1, 2).mean(axis=0)
    shrunk = (hull.reshape(-1, 2) - centre) * 0.92 + centre
    cv2.fillConvexPoly(image, np.round(shrunk).astype(np.int32), tuple(int(c) for c in mid), cv2.LINE_AA)
    for k, finger in enumerate(FINGERS):
        base_r = finger_r * (1.2 if k == 0 else 1.0)
        for j, (a, b) in enumerate(zip(finger[:-1], finger[1:])):
            r = base_r * (1.0 - 0.08 * j)
            _capsule(image, p[a], p[b], r, rim)
            _capsule(image, p[a], p[b], 0.8 * r, mid)
            _capsule(image, p[a], p[b], 0.45 * r, core)
    return image


def project(points_C: np.ndarray, camera_matrix: np.ndarray) -> np.ndarray:
    """Pinhole projection (no distortion) of points (N, 3) in the camera frame to pixels (N, 2)."""
    uvw = np.asarray(points_C, float) @ np.asarray(camera_matrix, float).T
    return uvw[:, :2] / uvw[:, 2:3]


def thumbs_up_U(wrist_U=(0.0, 0.0, 0.0), scale: float = 1.0) -> np.ndarray:
    """Keypoints (21, 3), metres, U: a right hand in a thumbs-up, knuckles to the person's left."""
    local = hand_keypoints_local(np.ones((1, 4)), np.zeros((1, 4)), np.deg2rad([[75.0, 5.0, 0.0, 0.0]]), scale)[0]
    R_UH = np.column_stack([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # thumb (-X of H) up
    return (local - local[0]) @ R_UH.T + np.asarray(wrist_U, float)


def drawn_hand_frames(calibration, script=(("wave", 2.5), ("gone", 1.5)), fps: float = 30.0,
                      amplitude_m: float = 0.03, period_s: float = 2.0, wrist_U=(0.0, 0.2, -0.02)):
    """Frames (BGR) of a drawn hand in front of the camera, following `script`.

    `script` is a list of (what, seconds): "wave", an open hand whose wrist moves
    along X of U, `amplitude_m` either side of `wrist_U` with period `period_s`;
    "thumbs_up", the pause sign held still; "gone", the background alone (the
    hand has left). Poses change from one frame to the next (MediaPipe may lose
    the hand for a frame there). Yields (frame, keypoints_U or None).
    """
    w, h = calibration.image_size_px
    K = calibration.camera_matrix()
    R_UC, p_UC = calibration.R_UC(), calibration.p_UC()
    empty = background(w, h)
    wrist = np.asarray(wrist_U, float)
    i = 0
    for what, seconds in script:
        for _ in range(int(round(seconds * fps))):
            if what == "gone":
                keypoints_U = None
            elif what == "thumbs_up":
                keypoints_U = thumbs_up_U(wrist + [0.0, 0.0, 0.04])
            elif what == "wave":
                x = amplitude_m * np.sin(2 * np.pi * (i / fps) / period_s)
                keypoints_U = open_hand_U(wrist + [x, 0.0, 0.0], curl=0.1)
            else:
                raise ValueError(f"unknown script step {what!r}")
            i += 1
            if keypoints_U is None:
                yield empty.copy(), None
            else:
                yield draw_hand(empty.copy(), project((keypoints_U - p_UC) @ R_UC, K)), keypoints_U


def write_video(path, frames, fps: float = 30.0) -> int:
    """Writes BGR frames to a Motion-JPEG `.avi` (any OpenCV build reads it); returns the frame count."""
    import cv2

    writer, count = None, 0
    for frame in frames:
        if writer is None:
            h, w = frame.shape[:2]
            writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
            if not writer.isOpened():
                raise RuntimeError(f"{path}: OpenCV cannot write a Motion-JPEG video here")
        writer.write(frame)
        count += 1
    if writer is not None:
        writer.release()
    return count
