"""The camera tracker's settings: the `camera` key of a scenario (see docs/interfaces.md)."""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc


@dc.dataclass
class Camera:
    """MediaPipe's thresholds and which hand the camera source follows."""

    # The most hands MediaPipe looks for in a frame; the hand rule below picks one. With fewer
    # hands in view than this MediaPipe runs its palm detector on every frame: 1 about halves the
    # tracker's time (README, "Measured figures"), but then MediaPipe alone picks the hand.
    num_hands: int = 2
    # MediaPipe's confidence thresholds (0..1): palm detection, hand presence, tracking.
    min_detection_confidence: float = 0.5
    min_presence_confidence: float = 0.5
    min_tracking_confidence: float = 0.5
    # Which of the person's hands gestures: "right", "left", or "largest" (the biggest in the image).
    hand: str = "right"
    # The camera image is mirrored (a selfie view), so MediaPipe's handedness labels are the person's own.
    mirrored: bool = False
