"""A recorded person in the closed loop: the simulated person's decisions, a real person's hand.

`RecordedPerson` is the `recorded` gesture source. It decides exactly as
the simulated person does (`InspectingPerson`: it sees the part late and
noisily, lifts, presents, turns each face toward the eye, holds it, and
stops a gesture when it sees the part arrive), and asks for one motion at a
time, since each recording holds a one-motion gesture. Its hand plays that
person's own recordings from a gesture dataset file (docs/interfaces.md,
"Recorded hands in the closed loop"):

- **Which recording.** For the motion wanted (Tx+ ... Rz-), a held-out
  recording (`split = test`) whose label commands that motion; when there
  are several, the next one in name order each time (cycling). Clips of
  the policy's context (`split = train`) are never played.
- **What is played.** The recording's gesture: its frames from the first to
  the last with a non-zero label, at the policy rate (the rest the importer
  adds around it is not played).
- **Long and short motions.** While the stroke's planned time is not over,
  a recording that ends is followed by the next; when the person sees the
  part arrive, the recording is cut there and the hand stays where it is.
- **Continuity.** Each recording is moved so that its palm centre starts
  where the hand's is, and the hand takes the recording's first shape before
  it plays (label zero meanwhile): the wrist on a straight line, each bone
  turning on the great circle, over 0.4 s or longer where a point would move
  faster than 0.25 m/s or a bone turn faster than 3 rad/s
  (`RecordedHandConfig`). The skeleton never jumps.
- **At rest** the hand holds still, with the person's own tracking noise:
  each frame's offset from the centred median of its 5 frames, from their
  held-out recordings' rest frames (label zero) where those move; where they
  do not (the SHREC'17 import holds its rest frames exactly still), from the
  gesture's frames where the palm moves slower than 0.05 m/s.

Input ports
  workpiece.pose  (7)  [x y z qw qx qy qz], world
Output ports
  gesture_features (36), gesture_status (2), keypoints (63): as every gesture source
  intended_twist  (6)  the label of the frame being played (m/s, rad/s, user frame);
                       zero at rest and while the hand takes a recording's first shape

`load_recorded_person(path, person, rate_hz)` reads what the source plays.
When the inspection asks for a motion the person has no held-out recording
of, the source raises an `InputError` naming the motion and the person (the
run command then writes its log and exits with status 2); the run command
warns of such motions at its start.
"""

from __future__ import annotations

import dataclasses as dc
import sys

import numpy as np

from rtcohand_drake.cell.geometry import smoothstep
from rtcohand_drake.data.dataset import DIMENSIONS
from rtcohand_drake.errors import InputError
from rtcohand_drake.systems.gestures.simulated_person import InspectingPerson, PersonConfig, PersonState

# The 12 one-motion commands (dimension, sign), Tx+, Tx-, ... Rz-: any of them may be asked for.
MOTIONS = tuple((d, s) for d in range(6) for s in (1, -1))
PALM = (0, 5, 9, 13, 17)  # wrist and the four finger bases: the palm centre is their mean


# Each keypoint's parent along the hand's chains (the wrist is the root): thumb 1-4, index 5-8, ...
PARENT = (-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19)


def blend_hands(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """(21, 3) the hand a share `w` of the way from skeleton `a` to skeleton `b`: the wrist moves on
    the straight line, each bone turns on the great circle and changes its length linearly. (A
    straight-line blend of the points can pass a bone through zero length, so that its direction
    flips within a frame.)"""
    out = np.empty((21, 3))
    out[0] = (1.0 - w) * a[0] + w * b[0]
    for k in range(1, 21):
        p = PARENT[k]
        u, v = a[k] - a[p], b[k] - b[p]
        lu, lv = np.linalg.norm(u), np.linalg.norm(v)
        if lu < 1e-9 or lv < 1e-9:
            out[k] = out[p] + (1.0 - w) * u + w * v
            continue
        u, v = u / lu, v / lv
        angle = float(np.arccos(np.clip(u @ v, -1.0, 1.0)))
        if angle < 1e-9:
            direction = u
        else:
            axis = np.cross(u, v)
            if np.linalg.norm(axis) < 1e-9:  # opposite: turn about any axis across the bone
                axis = np.cross(u, np.eye(3)[int(np.argmin(np.abs(u)))])
            axis = axis / np.linalg.norm(axis)
            turn = w * angle  # Rodrigues' rotation of u about the axis
            direction = u * np.cos(turn) + np.cross(axis, u) * np.sin(turn) + axis * (axis @ u) * (1 - np.cos(turn))
        out[k] = out[p] + ((1.0 - w) * lu + w * lv) * direction
    return out


def join_time(a: np.ndarray, b: np.ndarray, config: RecordedHandConfig) -> float:
    """Seconds for the hand to go from skeleton a to b at the join's speed and turn rate (0 when not finite)."""
    bones_a = a[1:] - a[list(PARENT[1:])]
    bones_b = b[1:] - b[list(PARENT[1:])]
    cos = np.sum(bones_a * bones_b, axis=1) / np.maximum(
        np.linalg.norm(bones_a, axis=1) * np.linalg.norm(bones_b, axis=1), 1e-12)
    turn = float(np.nanmax(np.arccos(np.clip(cos, -1.0, 1.0))))
    distance = float(np.nanmax(np.linalg.norm(b - a, axis=1)))
    time = max(distance / config.join_speed_m_s, turn / config.join_turn_rad_s)
    return time if np.isfinite(time) else 0.0


def motion_name(motion: tuple[int, int]) -> str:
    return f"{DIMENSIONS[motion[0]]}{'+' if motion[1] > 0 else '-'}"


@dc.dataclass
class RecordedHandConfig:
    """How the recorded hand joins its recordings and holds still."""

    # The hand takes a recording's first shape over at least `join_s` before it plays, longer when
    # a point of the hand has further to go than `join_speed_m_s` covers in that time, or a bone
    # further to turn than `join_turn_rad_s` does.
    join_s: float = 0.4
    join_speed_m_s: float = 0.25
    join_turn_rad_s: float = 3.0
    noise_window: int = 5  # tracking noise: each frame's offset from the median of this many frames
    still_m: float = 1e-6  # rest frames whose noise is all below this are held still by the file ...
    still_speed_m_s: float = 0.05  # ... and the noise is taken where the palm moves slower than this


@dc.dataclass(frozen=True, eq=False)
class Recording:
    """One held-out recording's gesture at the policy rate."""

    name: str  # USER/CLIP
    motion: tuple[int, int]
    keypoints: np.ndarray  # (T, 21, 3) m, user frame
    labels: np.ndarray  # (T, 6) m/s, rad/s


@dc.dataclass
class PersonRecordings:
    """What the recorded hand plays: recordings by motion (name order) and the tracking noise."""

    person: str
    by_motion: dict  # (dim, sign) -> [Recording, ...]
    noise: np.ndarray  # (M, 21, 3) m: successive offsets at the policy rate
    first: np.ndarray  # (21, 3): the hand before the first gesture (the first recording's first frame)
    path: str = ""  # the file they come from, for messages


def _motion_of(clip) -> tuple[int, int] | None:
    """The one motion a clip's label commands, or None (no label, several axes, or none moving)."""
    if clip.object_velocity is None or len(clip.active_dims) != 1:
        return None
    dim = int(clip.active_dims[0])
    total = float(np.sum(clip.object_velocity[:, dim]))
    return (dim, int(np.sign(total))) if total != 0.0 else None


def load_recorded_person(path, person: str, rate_hz: float, config: RecordedHandConfig | None = None
                         ) -> PersonRecordings:
    """A person's held-out recordings and tracking noise from a gesture dataset file (module doc)."""
    from rtcohand_drake.data.dataset import read_dataset
    from rtcohand_drake.data.hand_features import resample, slow_noise

    config = config or RecordedHandConfig()
    everyone = read_dataset(path)
    clips = [c for c in everyone if c.user == person]
    if not clips:
        users = sorted({c.user for c in everyone})
        raise InputError(f"{path}: no person named {person!r} (people: {', '.join(users[:12])}"
                         f"{', ...' if len(users) > 12 else ''})")
    held_out = sorted((c for c in clips if c.split == "test"), key=lambda c: c.clip_id)
    by_motion: dict = {m: [] for m in MOTIONS}
    rest_noise, still_noise = [], []
    for c in held_out:
        motion = _motion_of(c)
        if motion is None:
            continue
        kp = c.keypoints.astype(float)
        step = max(1, int(round(c.fps / rate_hz)))
        noise, slow = slow_noise(kp, c.fps, config.noise_window, config.still_speed_m_s)
        moving = np.abs(c.object_velocity).sum(axis=1) > 0
        rest_noise.append(noise[~moving][::step])
        still_noise.append(noise[moving & slow][::step])
        k0, k1 = np.flatnonzero(moving)[[0, -1]]
        times = c.times[k0:k1 + 1]
        kq, _ = resample(kp[k0:k1 + 1], times, rate_hz)
        labels, _ = resample(c.object_velocity[k0:k1 + 1].astype(float), times, rate_hz)
        if len(kq) >= 2:
            by_motion[motion].append(Recording(c.name, motion, kq, labels))
    rest = np.concatenate(rest_noise) if rest_noise else np.zeros((0, 21, 3))
    rest = rest[np.all(np.isfinite(rest), axis=(1, 2))]
    if len(rest) == 0 or float(np.max(np.abs(rest))) < config.still_m:
        rest = np.concatenate(still_noise) if still_noise else np.zeros((0, 21, 3))
        rest = rest[np.all(np.isfinite(rest), axis=(1, 2))]
    noise = rest if len(rest) else np.zeros((1, 21, 3))
    played = [r for rs in by_motion.values() for r in rs]
    if not played:
        raise InputError(f"{path}: person {person!r} has no held-out recording (split test) of a one-motion gesture")
    first = min(played, key=lambda r: r.name).keypoints[0]
    return PersonRecordings(person, by_motion, noise, first.copy(), str(path))


def missing_motions(recordings: PersonRecordings) -> list[str]:
    """The motions the person has no held-out recording of."""
    return [motion_name(m) for m in MOTIONS if not recordings.by_motion[m]]


@dc.dataclass
class RecordedHandState(PersonState):
    """The person's state plus the recorded hand's: which recording, where it plays, what it holds."""

    cycle: np.ndarray = dc.field(default_factory=lambda: np.zeros(len(MOTIONS), int))  # recordings played, by motion
    recording: tuple = (-1, -1)  # (index into MOTIONS, index of the recording) being joined or played
    frame: int = 0  # the next frame of it to play
    offset: np.ndarray = dc.field(default_factory=lambda: np.zeros(3))  # added to the recording, m
    join_from: np.ndarray = dc.field(default_factory=lambda: np.zeros((21, 3)))
    join_s: float = 0.0  # how long this join takes
    held: np.ndarray | None = None  # (21, 3) the still hand at rest
    noise_at: int = 0


class RecordedPerson(InspectingPerson):
    """The simulated person's decisions with a recorded person's hand (module doc)."""

    def __init__(self, recordings: PersonRecordings, X_WU, eye_W, config: PersonConfig | None = None,
                 hand: RecordedHandConfig | None = None, rate_hz: float = 10.0, seed: int = 0):
        super().__init__(recordings.person, X_WU, eye_W, config, rate_hz, seed, state_type=RecordedHandState)
        self.recordings = recordings
        self.hand = hand or RecordedHandConfig()

    def _plan(self, s, t, motions, goal, target, face, error, linear):
        # One motion a stroke: a part that drifted off while being turned is brought back first.
        if goal == "face" and len(motions) > 1 and motions[-1][0] < 3:
            motions, error, linear = motions[-1:], self.config.drift_tolerance_m, True
            s.last_face_turn = None
        stroke = super()._plan(s, t, motions[:1], goal, target, face, error, linear)
        # The gesture itself starts once the hand has taken the recording's first shape.
        stroke.t_on = stroke.t_on + self.hand.join_s
        stroke.t_plan_end = stroke.t_plan_end + self.hand.join_s
        return stroke

    def _recording(self, s: RecordedHandState) -> Recording:
        m, k = s.recording
        return self.recordings.by_motion[MOTIONS[m]][k]

    def _start_join(self, s: RecordedHandState, t: float) -> None:
        """The next recording of the stroke's motion, moved to start where the hand is."""
        m = MOTIONS.index(tuple(s.stroke.motions[0]))
        own = self.recordings.by_motion[MOTIONS[m]]
        if not own:
            raise InputError(f"{self.recordings.path}: person {self.recordings.person!r} has no held-out recording "
                             f"(split test) of {motion_name(MOTIONS[m])}, which the inspection asked for at {t:.1f} s")
        s.recording = (m, int(s.cycle[m] % len(own)))
        s.cycle[m] += 1
        s.join_from = s.keypoints.copy()
        first = self._recording(s).keypoints[0]
        s.offset = s.join_from[list(PALM)].mean(axis=0) - first[list(PALM)].mean(axis=0)
        s.join_s = max(self.hand.join_s, join_time(s.join_from, first + s.offset, self.hand))
        s.hand, s.hand_since, s.frame = "join", t, 0

    def _to_rest(self, s: RecordedHandState, t: float) -> None:
        s.hand, s.held, s.stroke = "rest", s.keypoints.copy(), None
        s.noise_at = int(s.rng.integers(len(self.recordings.noise)))
        s.rest_until = t + float(s.rng.uniform(*self.config.settle_s)) + float(s.rng.uniform(*self.config.pause_s))

    def _move_hand(self, s: RecordedHandState, t: float) -> None:
        s.intended = np.zeros(6)
        if s.held is None:  # before anything: the hand where the first recording starts
            s.keypoints, s.held = self.recordings.first.copy(), self.recordings.first.copy()
        if s.hand == "rest":
            if s.phase != "done" and t >= s.rest_until and s.start_U is not None:
                stroke = self._decide(s, t)
                if stroke is not None:
                    s.stroke = stroke
                    self._start_join(s, t)
            if s.hand == "rest":
                noise = self.recordings.noise
                s.keypoints = s.held + noise[s.noise_at % len(noise)]
                s.noise_at += 1
                return
        if s.hand == "join":
            u = (t - s.hand_since) / s.join_s if s.join_s > 0 else 1.0
            target = self._recording(s).keypoints[0] + s.offset
            if u < 1.0 - 1e-9:
                w = smoothstep(u)
                s.keypoints = blend_hands(s.join_from, target, w)
                return
            late = s.hand_since + s.join_s - s.stroke.t_on[0]
            if s.stroke.t_on[0] >= s.hand_since - 1e-9 and late > 0:  # a first join longer than planned
                s.stroke.t_on, s.stroke.t_plan_end = s.stroke.t_on + late, s.stroke.t_plan_end + late
            s.hand = "stroke"
        st = s.stroke
        self._stop_rule(s, t)
        if st.aborted or np.any(np.isfinite(st.t_off) & (st.t_off < st.t_plan_end)):
            self._to_rest(s, t)  # the part seen arriving (or going wrong): the recording is cut here
            s.keypoints = s.held.copy()
            return
        rec = self._recording(s)
        s.keypoints = rec.keypoints[s.frame] + s.offset
        s.intended = rec.labels[s.frame].copy()
        s.frame += 1
        if s.frame >= len(rec.keypoints):
            if t + self.period_s < st.t_plan_end[0]:
                self._start_join(s, t)  # a long motion: the gesture again
            else:
                self._to_rest(s, t)


def from_options(options, scenario):
    """The `recorded` source: person `options.clip` of `options.gesture_file`; its default context is
    that person's `split = train` clips of the same file."""
    from rtcohand_drake.cell.plant import eye_position
    from rtcohand_drake.data.dataset import load_policy_clips
    from rtcohand_drake.systems.gestures.registry import GestureSetup

    path, person = options.gesture_file, options.clip
    rate = scenario.policy.rate_hz
    recordings = load_recorded_person(path, person, rate)
    missing = missing_motions(recordings)
    if missing:
        print(f"warning: {path}: person {person!r} has no held-out recording of {', '.join(missing)}; the run "
              "stops with an error if the inspection asks for one", file=sys.stderr)
    source = RecordedPerson(recordings, scenario.cell.user_frame.to_rigid_transform(), eye_position(scenario.cell),
                            rate_hz=rate, seed=options.seed)

    def default_context(path_shape: bool = False):
        pieces = [(c.features, c.labels) for c in load_policy_clips(path, rate, path_shape)
                  if c.user == person and c.split == "train" and c.labels is not None]
        if not pieces:
            raise InputError(f"{path}: person {person!r} has no labelled split = train clips to use as context; "
                             "give one with --context-file PATH.h5 [--context-user USER]")
        return pieces

    return GestureSetup(source, default_context)
