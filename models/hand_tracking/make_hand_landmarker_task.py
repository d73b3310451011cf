"""Assembles `hand_landmarker.task` from the hand models inside the mediapipe 0.10.21 wheel.

    pip download mediapipe==0.10.21 --no-deps -d /tmp/wheel
    python models/hand_tracking/make_hand_landmarker_task.py /tmp/wheel/mediapipe-0.10.21-*.whl

A `.task` file is a zip holding `hand_detector.tflite` (the full palm
detection model) and `hand_landmarks_detector.tflite` (the full hand landmark
model), stored uncompressed; MediaPipe's Tasks API (mediapipe 1.x) reads it.
The lite palm model lacks the metadata the Tasks API needs. Run once, when
the bundle is made; the software reads the shipped file and downloads nothing.
"""

import hashlib
import sys
import zipfile
from pathlib import Path

MEMBERS = {"hand_detector.tflite": "mediapipe/modules/palm_detection/palm_detection_full.tflite",
           "hand_landmarks_detector.tflite": "mediapipe/modules/hand_landmark/hand_landmark_full.tflite"}


def main(wheel: str) -> None:
    out = Path(__file__).resolve().parent / "hand_landmarker.task"
    with zipfile.ZipFile(wheel) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as dst:
        for name, member in MEMBERS.items():
            data = src.read(member)
            dst.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)), data)  # byte-for-byte repeatable
            print(f"{name} <- {member} (sha256 {hashlib.sha256(data).hexdigest()})")
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1])
