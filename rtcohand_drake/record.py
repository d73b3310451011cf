"""`python -m rtcohand_drake.record`: record a person's own labelled clips, cued in Meshcat.

    python -m rtcohand_drake.record --out ME.h5 --user ME
        [--camera N | --video PATH | --simulated-user uXX [--population-seed N]]
        [--camera-calibration FILE] [--no-meshcat] [--only Tx+,Rz-] [--repeats 3] [--seed N] [--scenario S]
        [--labels cue|aruco [--marker-length-m 0.05] [--marker-id 0]] [--style hold|stroke] [--verbose]

The protocol is the paper's: for each target motion Meshcat shows a cue, a
workpiece moving the way the person should ask for, after a countdown; the
person gestures while watching it. The 12 one-motion clips (both signs of Tx,
Ty, Tz, Rx, Ry, Rz) come first, `--repeats` times over (3 by default: the
12 once, then again, and again), then the two-motion clips of `TWO_MOTIONS`
once. A person's read gains much from a second and third recording of each
gesture: the file for real hands reads the recorded development people's
held-out gestures at 0.64-0.85 of the error of commanding zero twist with
one recording of each in the context, and at 0.49-0.64 with three
(docs/real_people.md, section 6, "Recordings of each gesture in the
context"). A video recorded to the timeline of another `--repeats` needs the
same `--repeats` to be read.
The label of a clip is the cue's own twist, so no handler is needed; the file
records that (root attribute `label_source = "cue"`, docs/interfaces.md).
The cue leads the gesture by the person's response time, while the policy
was trained on labels that follow the gesture (a handler's, who reacts
late). So the labels are the cue's twist shifted later by
`Protocol.response_delay_s` + `Protocol.label_lag_s`; the file records the
shift (root attribute `label_delay_s`).
`--style` says how the person gestures, and the cue follows it:
- `hold` (the default): the person keeps moving or turning the hand for as
  long as the part should move; the cue moves for 2.5 s;
- `stroke`: the person makes one short stroke in the motion's direction
  (out, and back if they like), as many people do (recorded hands:
  docs/real_people.md); the cue moves faster for 1.2 s, at the speeds and
  ramps of the labels `data.import_shrec17` gives recorded strokes.
The style goes into the file (`recorder` attribute, `protocol.style`), and
the reading check gives advice for that style.

Clips are written per the gesture dataset contract, the person as the user
(group "out-sample", split "train"). Then the reading check
(`rtcohand_drake.analysis.context_reading`) runs on the new file and names
the motions read below half their size; the last lines give the command that
records just those again (`--only`, into a second file) and how to read both
files as one context (`--context-file FIRST.h5 SECOND.h5`).

`--labels aruco` is the paper's human-human protocol instead: a handler
moves an object carrying an ArUco marker in front of the camera as the
person gestures (the cue still shows the handler what to do); the marker's
pose (`rtcohand_drake.vision.aruco`) in each frame, in U, differentiated and
lightly smoothed, is the label (`label_source = "aruco"`, no shift: the
handler follows the gesture as the training data's handler did).

Where the gestures come from:
- `--camera N`: a webcam, live (`rtcohand_drake.vision.capture.LiveCameraTracker`);
- `--video PATH`: a video file of a session recorded to this protocol's
  timing (countdown, then the cue), played at its own frame rate;
- `--simulated-user uXX`: the built-in simulated person (a user of the
  generated population, `rtcohand_drake.data.population`) responds to each
  cue with their own gesture for that motion, after their perception delay
  (`PersonConfig.perception_delay_s` of the simulated person); the cue's
  timing and size follow that person's gesture for the motion. Headless and
  repeatable (`--seed`).
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.errors import ArgumentParser, InputError, non_negative_int, run_cli, writable_file_path

DIMENSIONS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
ONE_MOTIONS = tuple(((d, s),) for d in range(6) for s in (1, -1))
# Two-motion clips: a move with a turn, and two moves, in both sign combinations' common forms.
TWO_MOTIONS = (((0, 1), (1, 1)), ((1, -1), (2, 1)), ((2, 1), (5, 1)), ((0, -1), (4, -1)),
               ((1, 1), (3, -1)), ((3, 1), (5, -1)))
LABEL_SOURCE = "cue"
# Recordings of each one-motion gesture a session makes (`--repeats`). Chosen on recorded development
# people (experiments/context_repetitions_read.py): 1 -> 2 -> 3 recordings of each gesture in the
# context took the file for real hands' read from 0.83 to 0.57 to 0.52 (whole-hand) and from 0.64 to
# 0.54 to 0.49 (custom sets) of zero twist's error, close to all of theirs (2-5: 0.52, 0.47).
DEFAULT_REPEATS = 3


@dc.dataclass
class Protocol:
    """The recording session's timing and cue sizes (camera and video sessions)."""

    countdown_s: float = 3.0  # before each clip
    clip_s: float = 4.0  # one clip: the cue ramps up, holds, ramps down
    cue_start_s: float = 0.5  # the cue starts moving this long into the clip
    # ... and is still by then (s into the clip), so its labels, placed later, end within the clip
    cue_end_s: float = 3.0
    cue_ramp_s: float = 0.6
    cue_speed_m_s: float = 0.08  # the cue workpiece's speed on a translation
    cue_rate_rad_s: float = 0.5  # and its turn rate
    fps: float = 30.0  # the sampling of a live camera's keypoints
    # How late a person's gesture follows the cue (s): a visual reaction time (the simulated
    # person's perception delay is 0.1-0.25 s).
    response_delay_s: float = 0.15
    # How late the training data's labels follow a gesture (s): the generated handler's reaction
    # delay and smoothing, 0.25 s each on average (`GeneratorConfig.handler_delay_s`, `handler_lag_s`).
    # Chosen with benchmarks/recorded_context.py on simulated people u10 and u13 of population 0
    # (total shifts 0.45, 0.55, 0.65 s: 0.55 gave the lowest error).
    label_lag_s: float = 0.4
    style: str = "hold"  # how the person gestures: "hold" the motion, or one "stroke"


STYLES = ("hold", "stroke")
PROMPTS = {"hold": "gesture while the cue moves, and keep the motion going for as long as it moves",
           "stroke": "make one stroke in the cue's direction as it moves (out, and back if you like)"}


def protocol_for(style: str) -> Protocol:
    """The session's timing for a gesture style (module docstring)."""
    if style not in STYLES:
        raise InputError(f"command line: --style must be one of {', '.join(STYLES)}, got {style!r}")
    if style == "hold":
        return Protocol()
    # A stroke: the cue moves for 1.2 s at the speeds of the recorded people's labels
    # (data.import_shrec17: 0.12 m/s, 0.6 rad/s, 0.2 s ramps, about 1.1-2.5 s strokes), and the
    # clip is shorter; the shifted labels (0.55 s) still end within it.
    return Protocol(clip_s=3.0, cue_start_s=0.5, cue_end_s=1.7, cue_ramp_s=0.2, cue_speed_m_s=0.12,
                    cue_rate_rad_s=0.6, style="stroke")


def motion_name(motions) -> str:
    return "".join(DIMENSIONS[d] + ("+" if s > 0 else "-") for d, s in motions)


def session_motions(only: str | None, repeats: int) -> list[tuple[tuple[int, int], ...]]:
    """The clips a session records, in order: the one-motion clips (all 12, or those of `--only`) `repeats`
    times over, in rounds, then the two-motion clips (`TWO_MOTIONS`, or those of `--only`) once."""
    if not 1 <= repeats <= 10:
        raise InputError(f"command line: --repeats must be from 1 to 10, got {repeats}")
    motions = parse_only(only) if only else list(ONE_MOTIONS + TWO_MOTIONS)
    one = [m for m in motions if len(m) == 1]
    return one * repeats + [m for m in motions if len(m) > 1]


def parse_only(text: str) -> list[tuple[tuple[int, int], ...]]:
    """`Tx+,Rz-,Tx+Ty+` -> the motions to record (one- or two-motion names)."""
    out = []
    for item in (x.strip() for x in text.split(",")):
        motions, rest = [], item
        while rest:
            if len(rest) < 3 or rest[:2] not in DIMENSIONS or rest[2] not in "+-":
                raise InputError(f"command line: --only: {item!r} is not a motion like Tx+ or Tx+Ty-")
            motions.append((DIMENSIONS.index(rest[:2]), 1 if rest[2] == "+" else -1))
            rest = rest[3:]
        if not motions or len(motions) > 2 or len({d for d, _ in motions}) != len(motions):
            raise InputError(f"command line: --only: {item!r} needs one or two different dimensions")
        out.append(tuple(motions))
    return out


def cue_twist(motions, t: np.ndarray, protocol: Protocol) -> np.ndarray:
    """The cue workpiece's twist (N, 6) at clip times `t` (s): a smooth ramp up, hold, ramp down."""
    from rtcohand_drake.cell.geometry import smoothstep

    on, ramp = protocol.cue_start_s, protocol.cue_ramp_s
    off = min(protocol.cue_end_s, protocol.clip_s - protocol.cue_start_s)
    envelope = smoothstep((t - on) / ramp) * smoothstep((off - t) / ramp)
    twist = np.zeros((len(t), 6))
    for d, s in motions:
        twist[:, d] += s * (protocol.cue_speed_m_s if d < 3 else protocol.cue_rate_rad_s) * envelope
    return twist


# --------------------------------------------------------------------------- the cue in Meshcat


class CueView:
    """The cue in Meshcat: a workpiece-sized box that moves with the cue's twist (amber during the
    countdown, green while recording), in the user frame's axes."""

    def __init__(self, meshcat):
        from pydrake.geometry import Box, Rgba

        self._meshcat = meshcat
        self._rgba = {"countdown": Rgba(1.0, 0.7, 0.0, 1.0), "record": Rgba(0.1, 0.8, 0.2, 1.0)}
        self._box = Box(0.15, 0.10, 0.05)
        meshcat.SetObject("cue/workpiece", self._box, self._rgba["countdown"])

    def show(self, phase: str, pose_U: np.ndarray) -> None:
        from pydrake.common.eigen_geometry import Quaternion
        from pydrake.math import RigidTransform

        self._meshcat.SetObject("cue/workpiece", self._box, self._rgba[phase])
        q = pose_U[3:] / np.linalg.norm(pose_U[3:])
        self._meshcat.SetTransform("cue/workpiece", RigidTransform(Quaternion(q), pose_U[:3]))


# --------------------------------------------------------------------------- sessions


def record_simulated(user_id: str, motions_list, population_seed: int, seed: int, user: str,
                     style: str = "hold"):
    """The simulated person's clips for each cue: their gesture for the motion, their perception delay.

    With `style="stroke"` the same person makes each motion as one stroke (`UserProfile.single_stroke`,
    its return and speed drawn from a stream of their own)."""
    from rtcohand_drake.data.dataset import Clip
    from rtcohand_drake.data.population import GeneratorConfig, simulate_clip
    from rtcohand_drake.data.population.handler import integrate_pose
    from rtcohand_drake.data.population.people import make_user
    from rtcohand_drake.systems.gestures.simulated_person import PersonConfig, population_user_ids

    config = GeneratorConfig()
    ids = population_user_ids(config)
    if user_id not in ids:
        raise InputError(f"--simulated-user: unknown user {user_id!r}; valid ids: {', '.join(ids)}")
    index = list(ids).index(user_id)
    # The same person as the generated population's (the profile is the first draw of its stream).
    profile = make_user(config, user_id, ids[user_id], np.random.default_rng([int(population_seed), index]))
    if style == "stroke":
        stroke_rng = np.random.default_rng([int(population_seed), index, 2_000_003])
        profile.single_stroke = True
        profile.stroke_return = float(stroke_rng.uniform(*config.single_stroke_return))
        profile.stroke_speed_gain = float(stroke_rng.uniform(*config.single_stroke_speed_gain))
    rng = np.random.default_rng([int(population_seed), index, 1_000_003, int(seed)])
    delay_range = PersonConfig().perception_delay_s
    clips = []
    for k, motions in enumerate(motions_list):
        keypoints, _, _, truth = simulate_clip(config, profile, motions, rng)
        delay = float(rng.uniform(*delay_range))
        t = np.arange(len(keypoints)) / config.fps
        # The cue led the gesture by the person's perception delay; its size is what the gesture means.
        cue = np.stack([np.interp(t + delay, t, truth.intent[:, d], right=0.0) for d in range(6)], axis=1)
        pose = integrate_pose(np.asarray(config.object_start_position_m), cue, 1.0 / config.fps)
        clips.append(Clip(user=user, clip_id=f"{k:02d}_{motion_name(motions)}", group="out-sample",
                          split="train", active_dims=np.array(sorted(d for d, _ in motions), np.int64),
                          fps=config.fps, keypoints=keypoints, object_velocity=cue.astype(np.float32),
                          object_pose=pose.astype(np.float32),
                          description=f"cue {motion_name(motions)}; simulated person {user_id}, "
                                      f"perception delay {delay:.2f} s"))
        print(f"  {clips[-1].clip_id}: {len(keypoints) / config.fps:.1f} s", flush=True)
    return clips


def record_tracked(tracker, motions_list, protocol: Protocol, user: str, live: bool, view=None,
                   labels: str = LABEL_SOURCE):
    """Clips from a tracker: countdown, then the cue for `clip_s` while the keypoints are kept.

    `labels`: "cue" (the cue's twist) or "aruco" (the marked object's, `tracker.marker()`).

    `live`: a camera, paced by the wall clock; otherwise a video file, whose frames follow the
    same timeline (countdown then clip, back to back from its start).
    """
    from rtcohand_drake.data.dataset import Clip
    from rtcohand_drake.data.population.handler import integrate_pose

    start = np.array([0.0, 0.55, 0.0, 1.0, 0.0, 0.0, 0.0])  # the cue's pose at rest, U
    step = 1.0 / (protocol.fps if live else getattr(tracker, "fps", protocol.fps))
    wall0 = time.monotonic()
    t_session, clips = 0.0, []

    def wait_until(t):
        if live:
            time.sleep(max(0.0, wall0 + t - time.monotonic()))

    for k, motions in enumerate(motions_list):
        name = motion_name(motions)
        print(f"  clip {k + 1} of {len(motions_list)}, {name}: {PROMPTS[protocol.style]}", flush=True)
        for n in range(int(np.ceil(protocol.countdown_s)), 0, -1):
            print(f"  {name}: {n} ...", flush=True)
            if view is not None:
                view.show("countdown", start)
            wait_until(t_session + protocol.countdown_s - n + 1)
        t0 = t_session + protocol.countdown_s
        times, frames, markers, seen = [], [], [], None
        for i in range(int(round(protocol.clip_s / step))):
            t = t0 + i * step
            wait_until(t)
            keypoints, frame_time = tracker.latest(t)
            if frame_time == seen or not np.isfinite(frame_time):
                continue  # no new frame
            seen = frame_time
            times.append(frame_time - t0)
            frames.append(np.full((21, 3), np.nan) if keypoints is None else keypoints)
            markers.append(tracker.marker() if labels == "aruco" else None)
            if view is not None:
                cue_so_far = cue_twist(motions, np.arange(0.0, frame_time - t0 + 1e-9, step), protocol)
                view.show("record", integrate_pose(start[:3], cue_so_far, step)[-1])
        t_session = t0 + protocol.clip_s
        times = np.asarray(times)
        keep = np.concatenate([[True], np.diff(times) > 0]) if len(times) else np.zeros(0, bool)
        times, frames = times[keep], np.asarray(frames)[keep]
        markers = [m for m, k in zip(markers, keep) if k]
        if len(times) < 2 or np.all(np.isnan(frames)):
            print(f"  {name}: no hand seen; the clip is left out", flush=True)
            continue
        fps = 1.0 / float(np.median(np.diff(times)))
        cue = cue_twist(motions, times, protocol) if labels == "cue" else marker_labels(times, markers)
        if cue is None:
            print(f"  {name}: the marker was lost in most frames; the clip is left out", flush=True)
            continue
        clips.append(Clip(user=user, clip_id=f"{k:02d}_{name}", group="out-sample", split="train",
                          active_dims=np.array(sorted(d for d, _ in motions), np.int64), fps=max(fps, 5.0),
                          keypoints=frames.astype(np.float32), object_velocity=cue.astype(np.float32),
                          timestamps=times.astype(np.float64), description=f"cue {name}"))
    return clips


def align_labels(clips, delay_s: float):
    """Each clip's labels: its cue shifted later by `delay_s`, and the pose integrated from them."""
    from rtcohand_drake.data.population.handler import integrate_pose

    out = []
    for clip in clips:
        t = clip.times
        cue = clip.object_velocity.astype(float)
        label = np.stack([np.interp(t - delay_s, t, cue[:, d], left=0.0) for d in range(6)], axis=1)
        start = np.array([0.0, 0.55, 0.0]) if clip.object_pose is None else clip.object_pose[0, :3]
        pose = integrate_pose(np.asarray(start, float), label, 1.0 / clip.fps)
        out.append(dc.replace(clip, object_velocity=label.astype(np.float32), object_pose=pose.astype(np.float32)))
    return out


def marker_labels(times: np.ndarray, poses, smooth_frames: int = 5) -> np.ndarray | None:
    """Twists (N, 6) of the marked object from its poses [(R_UM, p_UM) or None]; lost frames filled
    in from their neighbours, a centred moving average over `smooth_frames`. None if mostly lost."""
    from rtcohand_drake.vision.aruco import twist_in_user_frame

    R = np.stack([np.full((3, 3), np.nan) if q is None else q[0] for q in poses])
    p = np.stack([np.full(3, np.nan) if q is None else q[1] for q in poses])
    twist = twist_in_user_frame(times, R, p)
    ok = np.all(np.isfinite(twist), axis=1)
    if ok.mean() < 0.5:
        return None
    filled = np.stack([np.interp(times, times[ok], twist[ok, d]) for d in range(6)], axis=1)
    kernel = np.ones(smooth_frames) / smooth_frames
    padded = np.pad(filled, ((smooth_frames // 2, smooth_frames // 2), (0, 0)), mode="edge")
    return np.stack([np.convolve(padded[:, d], kernel, mode="valid") for d in range(6)], axis=1)


def write_recording(path: Path, clips, protocol: Protocol, source: str, labels: str = LABEL_SOURCE,
                    repeats: int = 1) -> None:
    import h5py

    from rtcohand_drake.data.dataset import write_dataset

    write_dataset(path, clips)
    with h5py.File(path, "r+") as f:
        f.attrs["label_source"] = labels
        f.attrs["label_delay_s"] = protocol.response_delay_s + protocol.label_lag_s if labels == "cue" else 0.0
        f.attrs["recorder"] = json.dumps({"source": source, "protocol": dc.asdict(protocol), "repeats": repeats})


# --------------------------------------------------------------------------- command line


def make_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m rtcohand_drake.record", description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, required=True, help="the dataset file to write (HDF5)")
    p.add_argument("--user", required=True, help="the person's user id in the file")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--camera", type=non_negative_int, help="OpenCV camera number")
    src.add_argument("--video", type=Path, help="a video of a session recorded to this protocol's timing")
    src.add_argument("--simulated-user", help="the built-in simulated person uXX")
    p.add_argument("--population-seed", type=non_negative_int, default=0, help="with --simulated-user: the population")
    p.add_argument("--camera-calibration", type=Path, default=None, help="see python -m rtcohand_drake.run")
    p.add_argument("--scenario", default="inspection", help="scenario with the camera settings")
    p.add_argument("--only", default=None, help="record only these motions, e.g. Tx+,Rz- (default: all)")
    p.add_argument("--repeats", type=int, default=DEFAULT_REPEATS,
                   help=f"recordings of each one-motion gesture, in rounds (default {DEFAULT_REPEATS}); the "
                        "two-motion clips are recorded once")
    p.add_argument("--no-meshcat", action="store_true", help="no cue in Meshcat (headless)")
    p.add_argument("--no-check", action="store_true", help="skip the reading check at the end")
    p.add_argument("--model", type=Path, default=None,
                   help="the policy file the reading check reads the clips with (default: the scenario's "
                        "policy.model, or its policy.real_hand_model where one is named)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seeds the simulated person's responses")
    p.add_argument("--labels", choices=("cue", "aruco"), default="cue",
                   help="cue: the cue's twist; aruco: a handler's ArUco-marked object (camera or video)")
    p.add_argument("--marker-length-m", type=float, default=0.05, help="with --labels aruco: the marker's side")
    p.add_argument("--marker-id", type=non_negative_int, default=0, help="with --labels aruco: its id (DICT_4X4_50)")
    p.add_argument("--style", choices=STYLES, default="hold",
                   help="hold: keep the motion going while the part should move; stroke: one short stroke")
    p.add_argument("--verbose", action="store_true",
                   help="camera or video: show MediaPipe's and LiteRT's own INFO and WARNING lines on stderr "
                        "(hidden by default)")
    return p


def _check_before_recording(args):
    """What would otherwise fail only after the session is recorded: where it is written, the user id it
    is written under, the scenario (returned), and the policy file the reading check reads it with."""
    from rtcohand_drake.scenario import load_scenario

    writable_file_path(args.out, "--out")
    user = args.user
    if not user or user != user.strip() or "/" in user or user in (".", ".."):
        raise InputError(f"command line: --user {user!r}: give a non-empty id without '/' or surrounding spaces")
    scenario = load_scenario(args.scenario)
    if not args.no_check:
        from rtcohand_drake.cell.robot_files import policy_file_path
        from rtcohand_drake.learning.policy_file import check_policy_file

        named = getattr(scenario.policy, "real_hand_model", "") or scenario.policy.model
        check_policy_file(args.model if args.model is not None else policy_file_path(named))
    return scenario


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    scenario = _check_before_recording(args)
    motions_list = session_motions(args.only, args.repeats)
    protocol = protocol_for(args.style)
    print(f"recording {len(motions_list)} clips for {args.user}: "
          + ", ".join(motion_name(m) for m in motions_list), flush=True)
    if args.labels == "aruco" and args.simulated_user is not None:
        raise InputError("command line: --labels aruco needs --camera or --video (a handler's marked object)")
    if not args.marker_length_m > 0:
        raise InputError(f"command line: --marker-length-m must be > 0, got {args.marker_length_m}")
    if args.simulated_user is not None:
        if args.camera_calibration is not None:
            raise InputError("command line: --camera-calibration goes with --camera or --video")
        clips = record_simulated(args.simulated_user, motions_list, args.population_seed, args.seed, args.user,
                                 args.style)
        source = (f"simulated-user {args.simulated_user} (population seed {args.population_seed}, seed {args.seed}, "
                  f"style {args.style})")
    else:
        from rtcohand_drake.systems.gestures.camera import make_tracker

        marker = None
        if args.labels == "aruco":
            from rtcohand_drake.vision.aruco import MarkerConfig, MarkerTracker

            marker = MarkerTracker(MarkerConfig(marker_length_m=args.marker_length_m, marker_id=args.marker_id))
        tracker = make_tracker(scenario, args.camera, args.video, args.camera_calibration, marker_tracker=marker,
                               verbose=args.verbose)
        try:
            view = None
            if not args.no_meshcat:
                from pydrake.geometry import Meshcat, MeshcatParams

                meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
                print(f"Meshcat: {meshcat.web_url()} (the cue)", flush=True)
                view = CueView(meshcat)
            clips = record_tracked(tracker, motions_list, protocol, args.user, live=args.camera is not None,
                                   view=view, labels=args.labels)
        finally:
            tracker.close()
        source = f"camera {args.camera}" if args.camera is not None else f"video {args.video}"
    if not clips:
        raise InputError(f"{args.out}: no clip recorded (no hand was seen)")
    if args.labels == "cue":
        delay = protocol.response_delay_s + protocol.label_lag_s
        clips = align_labels(clips, delay)
        what = f"the cue's twist, {delay:.2f} s later"
    else:
        what = "the ArUco-marked object's twist"
    write_recording(args.out, clips, protocol, source, args.labels, args.repeats)
    print(f"wrote {len(clips)} clips of {args.user} to {args.out} (labels: {what})", flush=True)
    if args.no_check:
        return 0
    from rtcohand_drake.analysis import context_reading

    print("reading check:", flush=True)
    model = ["--model", str(args.model)] if args.model else []
    weak = context_reading.check(["--context-file", str(args.out), "--context-user", args.user,
                                  "--scenario", args.scenario] + model)
    missing = [motion_name(m) for m in ONE_MOTIONS
               if motion_name(m) not in {c.clip_id.split("_", 1)[1] for c in clips}]
    if missing and not args.only:
        print("not recorded (no hand seen): " + ", ".join(missing))
    else:
        missing = []
    print(again_hint(args, weak + [m for m in missing if m not in weak], model))
    return 0


def _source_flags(args) -> str:
    """The flags of this session that a second one, recording some motions again, needs the same: the
    source (a video names a new recording), its calibration and labels, the scenario, the cue's view."""
    if args.simulated_user is not None:
        flags = f" --simulated-user {args.simulated_user} --population-seed {args.population_seed} --seed {args.seed}"
    elif args.camera is not None:
        flags = f" --camera {args.camera}"
    else:
        flags = " --video NEW_VIDEO"
    if args.camera_calibration is not None:
        flags += f" --camera-calibration {args.camera_calibration}"
    if args.labels != "cue":
        flags += f" --labels {args.labels} --marker-length-m {args.marker_length_m:g} --marker-id {args.marker_id}"
    if args.scenario != "inspection":
        flags += f" --scenario {args.scenario}"
    return flags + (" --no-meshcat" if args.no_meshcat else "")


def again_hint(args, motions: Sequence[str], model: Sequence[str] = ()) -> str:
    """What to do about the motions the check read below half their size (or did not see): the
    command that records them again, and how to use both files as one context."""
    if not motions:
        return "every motion reads at least half its size: nothing to record again"
    again = args.out.with_name(f"{args.out.stem}_again{args.out.suffix or '.h5'}")
    both = f"--context-file {args.out} {again} --context-user {args.user}"
    return (f"to record {', '.join(motions)} again: python -m rtcohand_drake.record --out {again} "
            f"--user {args.user}{_source_flags(args)} --style {args.style} --only {','.join(motions)}"
            + (f" --repeats {args.repeats}" if args.repeats != DEFAULT_REPEATS else "") + "\n"
            f"then read both files' clips as one context: python -m rtcohand_drake.context_reading {both}"
            + "".join(f" {m}" for m in model) + " (python -m rtcohand_drake.run takes the same --context-file)")


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.record"))


if __name__ == "__main__":
    entry_point()
