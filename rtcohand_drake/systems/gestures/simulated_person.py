"""The built-in simulated person who inspects the part with their own gestures.

`SimulatedPerson` is the `synthetic` gesture source. It watches the
workpiece (with a perception delay and noise), decides what it wants next and
makes that user's own gestures for it, in closed loop, like a person would:

    lift     raise the part straight up out of the mold (+Tz only: nothing
             sideways while it is low, so it never touches the mold walls)
    present  bring it to a presentation point facing the inspector, composing
             two translation axes when both are far off; by default the point
             is where the lift ends (straight above the mold), so the turns
             start at once, where the arm turns the part best
    inspect  turn the nearest not-yet-seen face toward the inspector's eye
             (spin about the vertical, and tip about X or Y when still off:
             one or two rotation axes at once, plus a translation when the part
             has drifted), hold it there until it counts as seen, next face; a
             face the arm would not turn toward is tried again later
    done     all six faces seen: the hand rests

The hand itself is a small state machine: ``rest`` (reference gesture: palm
down, relaxed) -> ``stroke`` (the gesture for one or two motions, ramped up,
its intensity growing with the remaining error, ramped down when the person
sees the part will arrive, or when the planned stroke is over) -> ``return``
(the hand goes back to the reference gesture: lowered out of the camera's view
and raised again, or moved back in view, see `PersonConfig.return_mode`) ->
``rest``. Gestures come from the population model of
`rtcohand_drake.data.population` (the same strategies, hand, speeds, rhythm,
tremor and detector jitter as that user's dataset clips), so that user's own
labelled clips are the right context for the policy.

Input ports
  workpiece.pose  (7)  [x y z qw qx qy qz], world
Output ports (besides the `KeypointGestureSource` ones: gesture_features,
gesture_status, keypoints)
  intended_twist  (6)  the twist [vx vy vz wx wy wz] the person wants now, user
                       frame (m/s, rad/s; zero between gestures)

`make_builtin_person(scenario, seed, user)` builds the person for a user
of the generated population (default: the first out-sample user) and returns
that user's labelled clips as the policy's context. `KinematicWorkpiece` is a
stand-in for the robot that follows a twist exactly, for tests and notebooks.
"""

from __future__ import annotations

import copy
import dataclasses as dc

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector

from rtcohand_drake.data.population import (
    DEFAULT_SEED,
    DEFAULT_USERS,
    THUMB_REST_RAD,
    GeneratorConfig,
    UserProfile,
    gesture_envelope,
    hand_articulation,
    hand_keypoints_local,
    place_hand,
    relaxed_curl,
    rest_rotation,
    rotation_matrices,
    simulate_user,
    stroke_profile,
    user_groups,
)
from rtcohand_drake.errors import InputError
from rtcohand_drake.systems.gestures.base import NAN_HAND, KeypointGestureSource
from rtcohand_drake.cell.geometry import quaternion_to_matrix, rotation_vector, smoothstep
from rtcohand_drake.cell.faces import FACES
from rtcohand_drake.interfaces import INTENDED_TWIST, POSE_DIM, TWIST_DIM, WORKPIECE_POSE


FACE_NORMALS_E = np.array([face[1] for face in FACES], float)  # (6, 3)


@dc.dataclass
class PersonConfig:
    """The simulated person's habits. Pairs ``(lo, hi)`` are drawn once per person."""

    # Perception: the person sees the part late and not quite exactly.
    perception_delay_s: tuple[float, float] = (0.1, 0.25)
    perception_position_noise_m: float = 0.003
    perception_angle_noise_deg: float = 1.5
    velocity_window_s: float = 0.3  # the person judges the part's speed over this window
    # Task
    # Above the start, before anything sideways; by default also where the part is shown. With the
    # intent reference on development population 0, run seeds 0-2 (15 runs), lifting 0.18 / 0.26 /
    # 0.32 m gave median completions of 33.0 / 31.0 / 33.2 s: lower, the wrist comes within a few
    # centimetres of the table when the part is tipped; higher, joint 6 runs out of range sooner.
    lift_height_m: float = 0.26
    lift_tolerance_m: float = 0.025
    clear_height_m: float = 0.12  # below this (above the start) the person only lifts
    # While lifting, a part seen sliding sideways faster than this makes the person drop the hand at once.
    lift_sideways_stop_m_s: float = 0.02
    # Where the part is shown (world). None: straight above where it was first seen, at the lift
    # height, so the turns start as soon as the lift ends. The earlier point nearer the glass,
    # (0.25, 0.15, 0.50), cost two translation strokes (about 9 s) before the first turn
    # (docs/archive.md, "The presentation point and the intent reference on the earlier IK").
    presentation_xyz_W: tuple[float, float, float] | None = None
    presentation_tolerance_m: float = 0.07
    drift_tolerance_m: float = 0.12  # while inspecting, correct the position when further off
    # Faces are turned toward the eye about the vertical first (yaw), then tipped (tilt) if
    # still off by more than `tilt_needed_deg`; each turn stops this close to its goal.
    aim_angle_deg: float = 10.0
    tilt_needed_deg: float = 24.0
    seen_angle_deg: float = 30.0  # a face counts as seen within this angle ...
    hold_s: float = 0.8  # ... held this long
    # A face whose turns brought it less than `min_progress_deg` closer is tried later
    # (the arm could not turn that way from here): its choice costs `stuck_penalty_deg` more.
    min_progress_deg: float = 8.0
    stuck_penalty_deg: float = 60.0
    # Gestures
    intensity_range: tuple[float, float] = (0.8, 1.3)  # gesture intensity, small to large error
    full_error_m: float = 0.25  # errors this large or larger get the top intensity
    full_error_deg: float = 90.0
    compose_ratio: float = 0.45  # a second motion joins when its error is this share of the first's
    ramp_s: tuple[float, float] = (0.2, 0.45)  # ramp up / down of a gesture
    second_onset_jitter_s: float = 0.15
    min_stroke_s: float = 1.0  # planned full-activation time of a stroke
    max_stroke_s: float = 2.6
    expected_speed_m_s: float = 0.09  # how fast the person expects the part to follow
    expected_rate_rad_s: float = 0.5
    anticipation_s: float = 0.8  # the person stops gesturing this long before the part arrives
    settle_s: tuple[float, float] = (0.4, 0.7)  # hand still after a stroke
    pause_s: tuple[float, float] = (0.3, 0.7)  # rest (reference gesture) before the next gesture
    # "out_of_view": the hand drops out of the camera's view and comes back in the
    # reference gesture; "in_view": it moves back slowly, in view.
    return_mode: str = "out_of_view"
    out_of_view_s: tuple[float, float] = (0.6, 1.0)
    return_speed_fraction: float = 0.4  # in view: share of the user's gesture speed
    min_return_s: float = 0.6
    # Camera: single lost frames (0 = a tracker that bridges them)
    dropout_prob: float = 0.0


@dc.dataclass
class _Stroke:
    """One gesture: one or two motions (dim, sign), each with its own activation."""

    motions: tuple[tuple[int, int], ...]
    goal: str  # "lift" | "position" | "face"
    target: np.ndarray  # lift/position: goal position (3,) in U; face: unused
    face: int
    t_on: np.ndarray  # (k,) s
    t_off: np.ndarray  # (k,) s, inf until the person decides to stop
    t_plan_end: np.ndarray  # (k,) s, the planned end of full activation
    ramp_up: float
    ramp_down: float
    intensity: float
    phase0: float
    speeds: list[float]
    rates: list[float]
    drift: np.ndarray  # (k,) s of full-speed motion so far
    theta: np.ndarray  # (k,) rad, wrist turn angle so far (turn gestures)
    settle_s: float
    aborted: bool = False  # the person saw it go wrong and dropped the hand


@dc.dataclass
class PersonState:
    """Everything the simulated person carries from one policy period to the next."""

    rng: np.random.Generator
    delay_s: float
    tremor_phase: np.ndarray  # (2, 3) rad: rotation, position
    wander_freq_hz: np.ndarray  # (3,)
    wander_phase: np.ndarray  # (3,)
    t: float = -np.inf
    phase: str = "lift"
    start_U: np.ndarray | None = None  # where the part was first seen, U
    history: list = dc.field(default_factory=list)  # [(t, p_U (3,), R_UE (3, 3))], newest last
    seen: np.ndarray = dc.field(default_factory=lambda: np.zeros(6, bool))
    visible_since: np.ndarray = dc.field(default_factory=lambda: np.full(6, np.nan))
    hand: str = "rest"  # rest | stroke | return
    hand_since: float = 0.0
    rest_until: float = 0.0
    stroke: _Stroke | None = None
    # Hand configuration now: wrist displacement (3,) m and turn (3, 3) in U, fingers
    translation: np.ndarray = dc.field(default_factory=lambda: np.zeros(3))
    R_turn: np.ndarray = dc.field(default_factory=lambda: np.eye(3))
    curl: np.ndarray = dc.field(default_factory=lambda: np.zeros(4))
    abduction: np.ndarray = dc.field(default_factory=lambda: np.zeros(4))
    thumb: np.ndarray = dc.field(default_factory=lambda: THUMB_REST_RAD.copy())
    # Where a return starts from, and how long it takes
    return_from: tuple | None = None
    return_s: float = 0.0
    intended: np.ndarray = dc.field(default_factory=lambda: np.zeros(6))
    keypoints: np.ndarray = dc.field(default_factory=lambda: NAN_HAND.copy())
    strokes: int = 0
    face_penalty_deg: np.ndarray = dc.field(default_factory=lambda: np.zeros(6))
    last_face_turn: tuple | None = None  # (face, its angle when the turn began, deg)

    def __deepcopy__(self, memo):
        # Drake clones abstract state on every update; a generic deepcopy of this
        # state (and its generator) was a tenth of a headless run's wall time.
        # What is changed in place: arrays (here and in the stroke; copied), the
        # history list (appended and popped; its entries never change) and the
        # generator (its state copied). Tuples and lists of numbers are rebound.
        new = _copy_with_arrays(self)
        new.history = list(self.history)
        if self.stroke is not None:
            new.stroke = _copy_with_arrays(self.stroke)
        bits = type(self.rng.bit_generator)(0)
        bits.state = self.rng.bit_generator.state
        new.rng = np.random.Generator(bits)
        return new


def _copy_with_arrays(obj):
    """A shallow copy of a dataclass with its numpy array fields copied."""
    new = copy.copy(obj)
    for f in dc.fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, np.ndarray):
            setattr(new, f.name, value.copy())
    return new


class InspectingPerson(KeypointGestureSource):
    """The person's eyes and decisions (see module doc); the hand is the subclass's `_move_hand`.

    Each policy period the person sees the part (`_perceive`) and moves the hand
    (`_move_hand(s, t)`, which sets `s.keypoints` and `s.intended` and asks
    `_decide` for the next stroke when it is free). `SimulatedPerson` makes the
    gestures from a user's population model; `recorded_person.RecordedPerson`
    plays a recorded person's own gestures.
    """

    def __init__(self, person_id: str, X_WU, eye_W, config: PersonConfig | None = None, rate_hz: float = 10.0,
                 seed: int = 0, population_seed: int | None = None, state_type: type = PersonState,
                 **initial_fields):
        super().__init__(rate_hz)
        self.config = config or PersonConfig()
        self._R_UW = X_WU.rotation().matrix().T
        self._p_WU = X_WU.translation().copy()
        self.eye_U = self._to_U(np.asarray(eye_W, float))
        # None: where the lift ends, known once the part is first seen (`_presentation_U`).
        self.presentation_U = (None if self.config.presentation_xyz_W is None
                               else self._to_U(np.asarray(self.config.presentation_xyz_W, float)))

        # Deterministic in (seed, person): the person's own randomness (perception delay, tremor,
        # decision rhythm), apart from the dataset's. A person is a user id of a population: the
        # population's seed joins the key, so that u10 of population 101 is not u10 of 102 at the
        # joystick or as the intent reference either. The benchmark population (DEFAULT_SEED, or
        # None) keeps the key without it, so its runs are unchanged.
        key = [int(seed), 7351, *(ord(c) for c in person_id)]
        if population_seed is not None and int(population_seed) != DEFAULT_SEED:
            key += [8191, int(population_seed)]
        rng = np.random.default_rng(key)
        initial = state_type(
            rng=rng,
            delay_s=float(rng.uniform(*self.config.perception_delay_s)),
            tremor_phase=rng.uniform(0, 2 * np.pi, size=(2, 3)),
            wander_freq_hz=rng.uniform(0.2, 0.5, 3),
            wander_phase=rng.uniform(0, 6.3, 3),
            **initial_fields,
        )
        self._pose = self.DeclareVectorInputPort(WORKPIECE_POSE, POSE_DIM)
        self._state = self.DeclareAbstractState(AbstractValue.Make(initial))
        # Unrestricted updates run before the base class's discrete update at the same
        # time, so `keypoints_at` reads the skeleton of this period.
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.period_s, 0.0, self._advance)
        self.DeclareVectorOutputPort(INTENDED_TWIST, TWIST_DIM, self._calc_intended,
                                     prerequisites_of_calc={self.abstract_state_ticket(self._state)})

    def _move_hand(self, s: PersonState, t: float) -> None:
        raise NotImplementedError

    def _stroke_speeds(self, intensity: float, total_s: float) -> tuple[float, float]:
        """The hand's speed (m/s) and turn rate (rad/s) for a stroke; 0 where the hand does not use them."""
        return 0.0, 0.0

    # ------------------------------------------------------------------ Drake plumbing

    def keypoints_at(self, context) -> tuple[np.ndarray, float]:
        s = context.get_abstract_state(self._state).get_value()
        return s.keypoints, s.t

    def _calc_intended(self, context, output: BasicVector):
        output.SetFromVector(context.get_abstract_state(self._state).get_value().intended)

    def person_state(self, context) -> PersonState:
        """The person's state (phase, faces seen, hand mode, ...), for tests and notebooks."""
        return context.get_abstract_state(self._state).get_value()

    def _advance(self, context, state):
        s = copy.deepcopy(context.get_abstract_state(self._state).get_value())
        t = context.get_time()
        self._perceive(s, t, np.asarray(self._pose.Eval(context), float))
        self._move_hand(s, t)
        s.t = t
        state.get_mutable_abstract_state(self._state).set_value(s)

    # ------------------------------------------------------------------ perception

    def _to_U(self, p_W: np.ndarray) -> np.ndarray:
        return self._R_UW @ (p_W - self._p_WU)

    def _perceive(self, s: PersonState, t: float, pose_W: np.ndarray) -> None:
        p_U = self._to_U(pose_W[:3])
        R_UE = self._R_UW @ quaternion_to_matrix(pose_W[None, 3:7])[0]
        s.history.append((t, p_U, R_UE))
        keep = self.config.velocity_window_s + self.config.perception_delay_s[1] + 0.5
        while len(s.history) > 2 and s.history[1][0] < t - keep:
            s.history.pop(0)
        if s.start_U is None:
            s.start_U = p_U.copy()
        # Which faces the inspector sees, as the person sees them.
        p, R = self._seen_pose(s, t, noisy=True)
        angles = self._face_angles(p, R)
        for f in range(6):
            if angles[f] <= self.config.seen_angle_deg:
                if np.isnan(s.visible_since[f]):
                    s.visible_since[f] = t
                if t - s.visible_since[f] >= self.config.hold_s:
                    s.seen[f] = True
            else:
                s.visible_since[f] = np.nan

    def _seen_pose(self, s: PersonState, t: float, noisy: bool, age_s: float = 0.0):
        """The part's pose as the person saw it ``delay + age_s`` ago (U)."""
        when = t - s.delay_s - age_s
        entry = s.history[0]
        for e in s.history:
            if e[0] <= when + 1e-9:
                entry = e
        p, R = entry[1].copy(), entry[2].copy()
        if noisy:
            cfg = self.config
            p = p + s.rng.normal(0.0, cfg.perception_position_noise_m, 3)
            R = rotation_matrices(s.rng.normal(0.0, np.deg2rad(cfg.perception_angle_noise_deg), (1, 3)))[0] @ R
        return p, R

    def _face_angles(self, p_U: np.ndarray, R_UE: np.ndarray) -> np.ndarray:
        to_eye = self.eye_U - p_U
        to_eye = to_eye / np.linalg.norm(to_eye)
        normals = FACE_NORMALS_E @ R_UE.T
        return np.degrees(np.arccos(np.clip(normals @ to_eye, -1.0, 1.0)))

    def _velocity(self, s: PersonState, t: float) -> np.ndarray:
        w = self.config.velocity_window_s
        p1, _ = self._seen_pose(s, t, noisy=False)
        p0, _ = self._seen_pose(s, t, noisy=False, age_s=w)
        return (p1 - p0) / w

    # ------------------------------------------------------------------ decisions

    def _decide(self, s: PersonState, t: float) -> _Stroke | None:
        """What the person wants next, seen from rest: a stroke, or None (keep resting)."""
        cfg = self.config
        p, R = self._seen_pose(s, t, noisy=True)
        height = p[2] - s.start_U[2]
        if s.phase == "present" and height < cfg.clear_height_m:
            s.phase = "lift"  # too low to move sideways: straight up first
        if s.phase == "lift":
            if height < cfg.lift_height_m - cfg.lift_tolerance_m:
                goal = s.start_U + np.array([0.0, 0.0, cfg.lift_height_m])
                return self._plan(s, t, ((2, 1),), "lift", goal, -1, abs(goal[2] - p[2]), linear=True)
            s.phase = "present"
        if s.phase == "present":
            error = self._presentation_U(s) - p
            if np.linalg.norm(error) > cfg.presentation_tolerance_m:
                motions = self._translation_motions(error, cfg.presentation_tolerance_m)
                return self._plan(s, t, motions, "position", self._presentation_U(s), -1,
                                  float(np.linalg.norm(error)), linear=True)
            s.phase = "inspect"
        if s.phase == "inspect":
            if s.seen.all():
                s.phase = "done"
                return None
            angles = self._face_angles(p, R)
            if np.any(~s.seen & ~np.isnan(s.visible_since)):
                return None  # a new face is in view: hold it there
            if s.last_face_turn is not None:
                face, before = s.last_face_turn
                if before - angles[face] < cfg.min_progress_deg:
                    s.face_penalty_deg[face] += cfg.stuck_penalty_deg
                s.last_face_turn = None
            face = int(np.argmin(np.where(s.seen, np.inf, angles + s.face_penalty_deg)))
            motions = self._rotation_motions(p, R, face)
            s.last_face_turn = (face, float(angles[face]))
            error = self._presentation_U(s) - p
            if np.linalg.norm(error) > cfg.drift_tolerance_m:  # translate while turning
                motions = motions[:1] + self._translation_motions(error, cfg.drift_tolerance_m)[:1]
            return self._plan(s, t, motions, "face", self._presentation_U(s), face, angles[face], linear=False)
        return None

    def _presentation_U(self, s: PersonState) -> np.ndarray:
        """Where the part is shown, user frame (see `PersonConfig.presentation_xyz_W`)."""
        if self.presentation_U is not None:
            return self.presentation_U
        return s.start_U + np.array([0.0, 0.0, self.config.lift_height_m])

    def _translation_motions(self, error: np.ndarray, tolerance: float) -> tuple[tuple[int, int], ...]:
        order = np.argsort(-np.abs(error))
        motions = [(int(order[0]), int(np.sign(error[order[0]])))]
        second = error[order[1]]
        if abs(second) >= self.config.compose_ratio * abs(error[order[0]]) and abs(second) > 0.5 * tolerance:
            motions.append((int(order[1]), int(np.sign(second))))
        return tuple(motions)

    def _face_turns(self, p: np.ndarray, R: np.ndarray, face: int) -> np.ndarray:
        """Rotation (deg, about the axes of U) still needed to show `face`: [tilt x, tilt y, yaw z].

        A person spins the part about the vertical until the face looks the right way,
        then tips it toward the eye: yaw from the horizontal directions of the face normal
        and the line of sight, then the tilt that is left.
        """
        n = R @ FACE_NORMALS_E[face]
        to_eye = (self.eye_U - p) / np.linalg.norm(self.eye_U - p)
        yaw = 0.0
        if np.linalg.norm(n[:2]) > 0.35:  # a face that looks sideways: spin it round
            yaw = float(np.arctan2(n[0] * to_eye[1] - n[1] * to_eye[0], n[:2] @ to_eye[:2]))
        c, s_ = np.cos(yaw), np.sin(yaw)
        n = np.array([c * n[0] - s_ * n[1], s_ * n[0] + c * n[1], n[2]])
        axis = np.cross(n, to_eye)
        tilt = np.arccos(np.clip(n @ to_eye, -1.0, 1.0))
        if np.linalg.norm(axis) < 0.15:  # facing straight away: tip it over about X
            axis = np.array([1.0, 0.0, 0.0])
        axis = axis / np.linalg.norm(axis)
        return np.degrees(np.array([tilt * axis[0], tilt * axis[1], yaw]))

    def _rotation_motions(self, p: np.ndarray, R: np.ndarray, face: int) -> tuple[tuple[int, int], ...]:
        """The turns (yaw, and a tilt about X or Y when needed) that show `face`."""
        turns = self._face_turns(p, R, face)
        motions = []
        if abs(turns[2]) > self.config.aim_angle_deg:
            motions.append((5, int(np.sign(turns[2]))))
        tilt = turns[:2]
        if np.linalg.norm(tilt) > self.config.tilt_needed_deg or not motions:
            k = int(np.argmax(np.abs(tilt)))
            motions.append((3 + k, int(np.sign(tilt[k])) or 1))
        return tuple(motions)

    def _plan(self, s: PersonState, t: float, motions, goal: str, target: np.ndarray, face: int,
              error: float, linear: bool) -> _Stroke:
        cfg, rng = self.config, s.rng
        full = cfg.full_error_m if linear else np.deg2rad(cfg.full_error_deg)
        size = error if linear else np.deg2rad(error)
        lo, hi = cfg.intensity_range
        intensity = lo + (hi - lo) * min(size / full, 1.0)
        expected = cfg.expected_speed_m_s if linear else cfg.expected_rate_rad_s
        hold = float(np.clip(size / (expected * np.sqrt(intensity)), cfg.min_stroke_s, cfg.max_stroke_s))
        up, down = (float(rng.uniform(*cfg.ramp_s)) for _ in range(2))
        k = len(motions)
        t_on = t + np.array([0.0] + [float(rng.uniform(0.0, cfg.second_onset_jitter_s)) for _ in range(k - 1)])
        total = hold + 0.5 * (up + down)  # seconds of full activation, as the clips pace it
        speed, rate = self._stroke_speeds(intensity, total)
        s.strokes += 1
        return _Stroke(
            motions=tuple(motions), goal=goal, target=np.asarray(target, float).copy(), face=face,
            t_on=t_on, t_off=np.full(k, np.inf), t_plan_end=t_on + up + hold, ramp_up=up, ramp_down=down,
            intensity=intensity, phase0=float(rng.uniform(0, 2 * np.pi)), speeds=[speed] * k, rates=[rate] * k,
            drift=np.zeros(k), theta=np.zeros(k), settle_s=float(rng.uniform(*cfg.settle_s)))

    def _stop_rule(self, s: PersonState, t: float) -> None:
        """Ends the motions of the stroke whose goal the person sees coming (or whose plan is over)."""
        st, cfg = s.stroke, self.config
        if st.goal == "face":
            w = cfg.velocity_window_s
            turns = self._face_turns(*self._seen_pose(s, t, noisy=True), st.face)
            before = self._face_turns(*self._seen_pose(s, t, noisy=False, age_s=w), st.face)
        p, _ = self._seen_pose(s, t, noisy=True)
        v = self._velocity(s, t)
        tol = cfg.lift_tolerance_m if st.goal == "lift" else cfg.presentation_tolerance_m
        low = p[2] - s.start_U[2] < cfg.clear_height_m
        if st.goal == "lift" and low and np.linalg.norm(v[:2]) > cfg.lift_sideways_stop_m_s:
            st.t_off[:] = np.minimum(st.t_off, t)
            st.aborted = True
            return
        for k, (dim, sign) in enumerate(st.motions):
            if np.isfinite(st.t_off[k]) or t < st.t_on[k] + st.ramp_up:
                continue
            if dim >= 3:
                remaining = sign * turns[dim - 3]
                closing = max(sign * (before[dim - 3] - turns[dim - 3]) / cfg.velocity_window_s, 0.0)
                arrived = remaining <= closing * cfg.anticipation_s + cfg.aim_angle_deg
            else:
                remaining = sign * (st.target[dim] - p[dim])
                arrived = remaining <= max(sign * v[dim], 0.0) * cfg.anticipation_s + 0.5 * tol
            if arrived or t >= st.t_plan_end[k]:
                st.t_off[k] = t

class SimulatedPerson(InspectingPerson):
    """A simulated person who moves and turns the workpiece with one user's gestures (see module doc)."""

    def __init__(self, user: UserProfile, X_WU, eye_W, config: PersonConfig | None = None,
                 generator: GeneratorConfig | None = None, rate_hz: float = 10.0, seed: int = 0,
                 population_seed: int | None = None):
        relaxed = relaxed_curl(user)
        super().__init__(user.user_id, X_WU, eye_W, config, rate_hz, seed, population_seed, curl=relaxed.copy())
        self.user = user
        self.generator = generator or GeneratorConfig()
        if self.config.return_mode not in ("out_of_view", "in_view"):
            raise ValueError(f"return_mode must be 'out_of_view' or 'in_view', got {self.config.return_mode!r}")
        self._R_rest = rest_rotation(user)
        self._relaxed = relaxed

    def _stroke_speeds(self, intensity: float, total_s: float) -> tuple[float, float]:
        g = self.generator
        return (min(self.user.speed_m_s * intensity, 0.85 * g.max_excursion_m / total_s),
                min(self.user.rate_rad_s * intensity, 0.85 * g.max_turn_rad / total_s))

    # ------------------------------------------------------------------ the hand

    def _move_hand(self, s: PersonState, t: float) -> None:
        cfg = self.config
        s.intended = np.zeros(6)
        visible = True
        if s.hand == "rest":
            self._rest_hand(s)
            if s.phase != "done" and t >= s.rest_until and s.start_U is not None:
                stroke = self._decide(s, t)
                if stroke is not None:
                    s.stroke, s.hand, s.hand_since = stroke, "stroke", t
        if s.hand == "stroke":
            st = s.stroke
            self._stop_rule(s, t)
            self._articulate(s, t)
            a = self._activations(st, np.array([t]))[:, 0]
            for k, (dim, sign) in enumerate(st.motions):
                expected = cfg.expected_speed_m_s if dim < 3 else cfg.expected_rate_rad_s
                s.intended[dim] += sign * expected * np.sqrt(st.intensity) * a[k]
            ended = np.all(np.isfinite(st.t_off)) and t >= np.max(st.t_off) + st.ramp_down + st.settle_s
            ended = ended or (st.aborted and cfg.return_mode == "out_of_view")
            if ended:
                s.hand, s.hand_since = "return", t
                s.return_from = (s.translation.copy(), s.R_turn.copy(), s.curl.copy(), s.abduction.copy(),
                                 s.thumb.copy())
                if cfg.return_mode == "out_of_view":
                    s.return_s = float(s.rng.uniform(*cfg.out_of_view_s))
                else:
                    dist = np.linalg.norm(s.translation) / (cfg.return_speed_fraction * self.user.speed_m_s)
                    turn = np.linalg.norm(rotation_vector(s.R_turn)) / (cfg.return_speed_fraction * self.user.rate_rad_s)
                    s.return_s = max(cfg.min_return_s, dist, turn)
                s.stroke = None
        if s.hand == "return":
            tau = (t - s.hand_since) / s.return_s
            if cfg.return_mode == "out_of_view":
                visible = tau >= 1.0
                if visible:
                    self._rest_hand(s)
            else:
                self._blend_to_rest(s, smoothstep(tau))
            if tau >= 1.0:
                s.hand = "rest"
                s.rest_until = t + float(s.rng.uniform(*cfg.pause_s))
        s.keypoints = self._skeleton(s, t) if visible else NAN_HAND.copy()
        if visible and cfg.dropout_prob > 0 and s.rng.random() < cfg.dropout_prob:
            s.keypoints = NAN_HAND.copy()

    def _rest_hand(self, s: PersonState) -> None:
        s.translation, s.R_turn = np.zeros(3), np.eye(3)
        s.curl, s.abduction, s.thumb = self._relaxed.copy(), np.zeros(4), THUMB_REST_RAD.copy()

    def _blend_to_rest(self, s: PersonState, u: float) -> None:
        tr, R, curl, abd, thumb = s.return_from
        s.translation = (1.0 - u) * tr
        s.R_turn = rotation_matrices(((1.0 - u) * rotation_vector(R))[None])[0]
        s.curl = (1.0 - u) * curl + u * self._relaxed
        s.abduction = (1.0 - u) * abd
        s.thumb = (1.0 - u) * thumb + u * THUMB_REST_RAD

    def _activations(self, st: _Stroke, times: np.ndarray) -> np.ndarray:
        return np.array([gesture_envelope(times, st.t_on[k], st.ramp_up, st.t_off[k], st.ramp_down)
                         for k in range(len(st.motions))])

    def _articulate(self, s: PersonState, t: float) -> None:
        """Advances the stroke's hand motion over the last period, in camera frames."""
        st, g = s.stroke, self.generator
        n_sub = max(1, int(round(self.period_s * g.fps)))
        times = t - self.period_s + self.period_s * np.arange(1, n_sub + 1) / n_sub
        times = times[times >= st.t_on[0] - 1e-9]  # the stroke starts at a period: t itself stays
        dt = self.period_s / n_sub
        env = self._activations(st, times)
        drifts = [st.drift[k] + np.cumsum(stroke_profile(self.user, env[k], times, st.phase0)) * dt
                  for k in range(len(st.motions))]
        curl, abd, thumb, translation, turns = hand_articulation(
            g, self.user, st.motions, list(env), drifts, st.speeds, st.rates, times, st.intensity,
            st.phase0, float(st.t_on[0]))
        # Wrist turns: the angular velocities about axes of U add up, integrated frame by frame.
        turn_of = {}
        for k, (dim, sign) in enumerate(st.motions):
            if self.user.gestures[(dim, sign)].kind in ("turn", "turn_move"):
                turn_of[k] = len(turn_of)
        for i in range(times.size):
            omega = np.zeros(3)
            for k, j in turn_of.items():
                axis, theta = turns[j]
                omega[axis] += theta[i] - st.theta[k]
                st.theta[k] = theta[i]
            if np.any(omega):
                s.R_turn = rotation_matrices(omega[None])[0] @ s.R_turn
        st.drift = np.array([d[-1] for d in drifts])
        s.translation, s.curl, s.abduction, s.thumb = translation[-1], curl[-1], abd[-1], thumb[-1]

    def _skeleton(self, s: PersonState, t: float) -> np.ndarray:
        u, g = self.user, self.generator
        local = hand_keypoints_local(s.curl[None], s.abduction[None], s.thumb[None], u.hand_scale)
        tremor_rot = u.tremor_rotation_rad * np.sin(2 * np.pi * u.tremor_freq_hz * t + s.tremor_phase[0])
        R = rotation_matrices(tremor_rot[None])[0] @ s.R_turn @ self._R_rest
        wander = g.wander_position_m * np.sin(2 * np.pi * s.wander_freq_hz * t + s.wander_phase)
        tremor_pos = u.tremor_position_m * np.sin(2 * np.pi * u.tremor_freq_hz * t + s.tremor_phase[1])
        clean = place_hand(u, local, R[None], s.translation[None], wander[None], tremor_pos[None])[0]
        return clean + s.rng.normal(0.0, g.jitter_m, size=clean.shape)


def population_user_ids(config: GeneratorConfig | None = None, n_users: int = DEFAULT_USERS) -> dict[str, str]:
    """User id -> group of the default generated population (as `data.generate` names them)."""
    config = config or GeneratorConfig()
    return {f"u{i:02d}": group for i, group in enumerate(user_groups(n_users, config))}


def make_builtin_person(scenario, seed: int = 0, user: str | None = None,
                          config: PersonConfig | None = None, population_seed: int = DEFAULT_SEED,
                          path_shape: bool = False, generator: GeneratorConfig | None = None):
    """The built-in simulated person and its context: (SimulatedPerson, [(features (T, 36), labels (T, 6)), ...]);
    with `path_shape` the features are followed by the hand's path and shape (`to_policy_clip`).

    The person is a user of the population `python -m rtcohand_drake.data.generate`
    writes by default (15 users, seed 0): `user` names one by id ("u00" ..
    "u14"); by default the first out-sample user, whom no policy was trained on.
    The context is that user's 72 labelled clips at the policy rate, generated
    here exactly as in that file. `population_seed` picks another population
    (as `data.generate --seed N` writes it): people other than the benchmark's,
    to validate a design choice on; `generator` a population drawn with other
    settings (as `data.generate --direct-share 1` writes it, say).
    """
    from rtcohand_drake.data.dataset import to_policy_clip
    from rtcohand_drake.cell.plant import eye_position

    generator = generator or GeneratorConfig()
    ids = population_user_ids(generator)
    if user is None:
        user = next(u for u, group in ids.items() if group == "out-sample")
    if user not in ids:
        out = [u for u, g in ids.items() if g == "out-sample"]
        raise InputError(f"--user: unknown user {user!r}; valid ids: {', '.join(ids)} "
                         f"(out-sample: {', '.join(out)})")
    index = list(ids).index(user)
    profile, clips, _ = simulate_user(generator, index, ids[user], population_seed)
    rate = scenario.policy.rate_hz
    pieces = []
    for clip in clips:
        pc = to_policy_clip(clip, rate, path_shape)
        pieces.append((pc.features, pc.labels))
    X_WU = scenario.cell.user_frame.to_rigid_transform()
    person = SimulatedPerson(profile, X_WU, eye_position(scenario.cell), config, generator, rate, seed,
                             population_seed=population_seed)
    return person, pieces


def from_options(options, scenario):
    """The `synthetic` source: the built-in simulated person (`options.user`, `options.population_seed`,
    `options.seed`); its default context is that person's own generated labelled clips."""
    from rtcohand_drake.systems.gestures.registry import GestureSetup

    population = DEFAULT_SEED if options.population_seed is None else options.population_seed
    person, pieces = make_builtin_person(scenario, seed=options.seed, user=options.user, population_seed=population)

    def context(path_shape: bool = False):
        if not path_shape:
            return pieces
        # The same person's clips again (deterministic in the population seed), with the wider features.
        return make_builtin_person(scenario, seed=options.seed, user=options.user, population_seed=population,
                                   path_shape=True)[1]
    return GestureSetup(person, context)
