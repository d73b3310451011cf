"""The camera tracker's settings: the `camera` key of a scenario (see docs/interfaces.md)."""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc


@dc.dataclass
class PoseFilter:
    """How the hand is held steady in depth (`rtcohand_drake.vision.hand_pose_filter`; docs/own_hand.md).

    Each frame's metric fit places the hand at a depth set by MediaPipe's guess of
    its size in that frame; these settings fix the size and smooth what is left.
    """

    enabled: bool = True
    # Where the palm's depth comes from, all with the person's hand size fixed:
    # "palm_spans": the depth at which the least foreshortened of the palm's rigid spans (wrist to
    # each knuckle, index to pinky knuckle) has the person's length for it; "fixed_palm": the fit,
    # rescaled as if MediaPipe's hand had the person's palm size; "fit": the fit as it is (no fixing).
    depth_cue: str = "palm_spans"
    # The person's palm size (m: the mean length of those spans); 0: MediaPipe's metric hand's, the
    # median over the first `palm_size_from_first_s` (s) of tracking. Either is kept for the run.
    palm_size_m: float = 0.0
    palm_size_from_first_s: float = 1.0
    # Smoothing of the palm's depth: "one_euro" (Casiez et al. 2012), "kalman" (constant velocity), "none".
    smoother: str = "one_euro"
    # One Euro: the cutoff at rest (Hz), its rise with the depth speed (Hz per m/s), the speed's cutoff (Hz).
    min_cutoff_hz: float = 1.0
    beta_hz_per_m_s: float = 20.0
    derivative_cutoff_hz: float = 1.0
    # Kalman: the hand's random acceleration (m/s^2, one sigma) and the depth's noise in a frame (m).
    kalman_accel_m_s2: float = 3.0
    kalman_depth_noise_m: float = 0.02
    # A frame whose depth is further from the last steady depth than this speed allows (m/s, over the
    # frame's interval, plus `jump_floor_m`) is held at that depth, one frame at most: a single-frame jump.
    max_depth_speed_m_s: float = 1.5
    jump_floor_m: float = 0.03
    # After the hand has been lost this long (s) the depth starts afresh from the next frame.
    reset_after_s: float = 0.5


@dc.dataclass
class Camera:
    """MediaPipe's thresholds and which hand the camera source follows."""

    # The most hands MediaPipe looks for in a frame; the hand rule below picks one. With fewer
    # hands in view than this MediaPipe runs its palm detector on every frame: 1 about halves the
    # tracker's time (docs/benchmarks.md, the camera source), but then MediaPipe alone picks the hand.
    num_hands: int = 2
    # MediaPipe's confidence thresholds (0..1): palm detection, hand presence, tracking.
    min_detection_confidence: float = 0.5
    min_presence_confidence: float = 0.5
    min_tracking_confidence: float = 0.5
    # Which of the person's hands gestures: "right", "left", or "largest" (the biggest in the image).
    hand: str = "right"
    # The camera image is mirrored (a selfie view), so MediaPipe's handedness labels are the person's own.
    mirrored: bool = False
    # A Gaussian blur of this sigma (px; its kernel spans about 2 sigma either side) before MediaPipe;
    # 0: none. Pixel noise (a GIF's dithered palette) hides hands from the palm detector (docs/own_hand.md).
    blur_sigma_px: float = 0.65
    # Holding the hand steady in depth.
    pose_filter: PoseFilter = dc.field(default_factory=PoseFilter)
