"""Import recorded people: the SHREC'17 hand-gesture skeletons into the gesture dataset file.

    python -m rtcohand_drake.data.import_shrec17 --root DIR --out FILE.h5
        [--mapping natural|whole-hand|custom] [--subjects S ...] [--seed N] [--group out-sample|in-sample]
        [--rest-s 0.5] [--ramp-s 0.2] [--rest-noise]

DIR is the dataset as it ships (De Smedt et al., "SHREC'17 Track: 3D Hand
Gesture Recognition Using a Depth and Skeletal Dataset", 3DOR 2017):
``gesture_G/finger_F/subject_S/essai_E/skeletons_world.txt``, one frame a line,
22 joints x (x y z) in metres, about 30 frames per second. G = 1..14 is the
gesture class (`GESTURES`), F = 1 one finger, F = 2 the whole hand; a
*variant* is a (G, F) pair, 28 in all.

What a recorded person becomes (docs/interfaces.md, recorded people):

- **Who commands what.** Each person gets a command map: which variant
  commands which of the 12 one-motion commands Tx+, Tx-, Ty+, ... Rz-
  (`COMMANDS`). ``natural`` is one fixed map for everyone (`NATURAL_MAP`:
  swipes move, rotations turn, the rest by the whole hand; the whole hand's
  and one finger's rotations both turn, so one motion comes in two
  postures); ``whole-hand`` is one fixed map with all 12 gestures made with
  the whole hand (`WHOLE_HAND_MAP`); ``custom`` draws
  12 of the person's variants at random for each person (seeded by ``--seed``
  and the subject), as a person who chooses their own gestures would.
- **Keypoints in U.** Joint 1 (the palm centre) is dropped, which leaves the
  project's 21-point order. The camera frame has x to the person's right,
  y up and z the depth away from the camera, toward the person; U has X
  right, Y forward (away from the person) and Z up, so
  ``X_U = x``, ``Y_U = -z``, ``Z_U = y`` (a proper rotation).
- **Rest.** The sequences are trimmed to the gesture; the first frame is held
  still for ``rest_s`` before it and the last frame for ``rest_s`` after it,
  so each clip starts and ends at rest as a recorded clip does. With
  ``--rest-noise`` the held frames carry the person's own tracking jitter
  instead of none: successive offsets of their frames from a 5-frame median,
  taken where the palm moves slower than 0.05 m/s in any of their mapped
  sequences (`hand_features.slow_noise`), from a point drawn for each rest
  (seeded by ``--seed`` and the subject), as a tracked hand at rest jitters.
- **Labels.** Over the gesture's frames the command's twist at the project's
  magnitudes (`TRANSLATION_M_S`, `ROTATION_RAD_S`), ramped linearly over
  ``ramp_s`` at each end inside the gesture; zero over the rests.
- **Splits.** Of each mapped variant, the last repetition is ``test`` (held
  out) and the others ``train`` (the person's context); a variant recorded
  only once gives no held-out clip (its one clip is context). With
  ``--held-out N`` the last N repetitions are held out, the first always
  stays in the context; a recorded person (`run --gesture-source recorded`)
  then cycles through them, as a person varies a gesture they repeat. The
  ``Person`` evaluation setting reads each person's test clips with their
  own train clips as context (`rtcohand_drake.data.sampling`).

The map and the labelling are stored in the file: the root attribute
``import`` (JSON: source, mapping, seed, rest_s, ramp_s, rest, magnitudes, axis map)
and each user's attribute ``command_map`` (JSON: command -> "G<g>F<f>"); each
clip's ``description`` names its gesture, finger, repetition and command.

Bad input (a missing folder, an unreadable or malformed skeleton file, a row
of the wrong length) is one line naming the file and the problem, exit 2.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from rtcohand_drake.data.dataset import DIMENSIONS, Clip, write_dataset
from rtcohand_drake.errors import ArgumentParser, InputError, non_negative_int, run_cli

FPS = 30.0  # the SR300 skeleton stream's rate (dataset description)
NUM_JOINTS = 22
PALM_JOINT = 1  # the dataset's extra joint; without it the order is the project's 21-point hand
GESTURES = ("Grab", "Tap", "Expand", "Pinch", "Rotation CW", "Rotation CCW", "Swipe Right", "Swipe Left",
            "Swipe Up", "Swipe Down", "Swipe X", "Swipe +", "Swipe V", "Shake")  # G = 1..14
FINGERS = ("one finger", "whole hand")  # F = 1, 2
# The 12 one-motion commands, (dimension, sign), in the order Tx+, Tx-, Ty+, Ty-, ... Rz+, Rz-.
COMMANDS = tuple((d, s) for d in range(6) for s in (1, -1))
# The project's label magnitudes: the simulated handler's nominal object speed and turn rate
# (rtcohand_drake.data.population.config, handler_speed_m_s and handler_rate_rad_s, upper halves).
TRANSLATION_M_S = 0.12
ROTATION_RAD_S = 0.6
# Camera (x right, y up, z depth toward the person) -> U (X right, Y forward, Z up): rows of R_UC.
R_UC = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

# natural: swipes of the whole hand move across and up/down, a tap pushes and a grab pulls; the
# rotations turn about the forward axis (whole hand) and the vertical one (one finger); an expand
# and a pinch tilt about the across axis.
NATURAL_MAP = {
    "Tx+": (7, 2), "Tx-": (8, 2), "Ty+": (2, 2), "Ty-": (1, 2), "Tz+": (9, 2), "Tz-": (10, 2),
    "Rx+": (3, 2), "Rx-": (4, 2), "Ry+": (5, 2), "Ry-": (6, 2), "Rz+": (6, 1), "Rz-": (5, 1),
}
# whole-hand: all 12 gestures made with the whole hand, each motion by one gesture: swipes right/left
# and up/down move across and up/down, an expand pushes and a grab pulls, the rotations turn about
# the vertical axis, a tap and a pinch tilt about the across axis, a swipe V and a swipe + about the
# forward one.
WHOLE_HAND_MAP = {
    "Tx+": (7, 2), "Tx-": (8, 2), "Ty+": (3, 2), "Ty-": (1, 2), "Tz+": (9, 2), "Tz-": (10, 2),
    "Rx+": (2, 2), "Rx-": (4, 2), "Ry+": (13, 2), "Ry-": (12, 2), "Rz+": (6, 2), "Rz-": (5, 2),
}
FIXED_MAPS = {"natural": NATURAL_MAP, "whole-hand": WHOLE_HAND_MAP}
MAPPINGS = ("natural", "whole-hand", "custom")

_PATH = re.compile(r"gesture_(\d+)/finger_(\d+)/subject_(\d+)/essai_(\d+)/skeletons_world\.txt$")


def command_name(dim: int, sign: int) -> str:
    return f"{DIMENSIONS[dim]}{'+' if sign > 0 else '-'}"


COMMAND_NAMES = tuple(command_name(d, s) for d, s in COMMANDS)


@dataclass(frozen=True)
class Sequence17:
    """One recorded sequence: its variant, subject, repetition and skeleton file."""

    gesture: int
    finger: int
    subject: int
    essai: int
    path: Path

    @property
    def variant(self) -> tuple[int, int]:
        return (self.gesture, self.finger)


def find_sequences(root: Path) -> list[Sequence17]:
    """Every skeleton file under `root`, in (subject, gesture, finger, essai) order."""
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder (the SHREC'17 root holds gesture_1 .. gesture_14)")
    found = []
    for path in root.glob("gesture_*/finger_*/subject_*/essai_*/skeletons_world.txt"):
        m = _PATH.search(path.relative_to(root).as_posix())
        if m:
            g, f, s, e = (int(v) for v in m.groups())
            if 1 <= g <= len(GESTURES) and f in (1, 2):
                found.append(Sequence17(g, f, s, e, path))
    if not found:
        raise InputError(f"{root}: no gesture_G/finger_F/subject_S/essai_E/skeletons_world.txt files found")
    return sorted(found, key=lambda q: (q.subject, q.gesture, q.finger, q.essai))


def read_skeletons(path: Path) -> np.ndarray:
    """(N, 22, 3) float64 from one skeleton file; a malformed file is an InputError naming it and the line."""
    try:
        lines = Path(path).read_text().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read ({err.__class__.__name__})") from None
    rows = []
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        tokens = line.split()
        if len(tokens) != NUM_JOINTS * 3:
            raise InputError(f"{path}: line {i} has {len(tokens)} values, expected {NUM_JOINTS * 3} (22 joints x 3)")
        try:
            row = [float(t) for t in tokens]
        except ValueError:
            raise InputError(f"{path}: line {i} is not numbers") from None
        if not np.all(np.isfinite(row)):
            raise InputError(f"{path}: line {i} has a non-finite value")
        rows.append(row)
    if len(rows) < 2:
        raise InputError(f"{path}: {len(rows)} frames; a gesture needs at least 2")
    return np.asarray(rows).reshape(-1, NUM_JOINTS, 3)


def to_user_frame(skeletons: np.ndarray) -> np.ndarray:
    """(N, 22, 3) camera-frame joints -> (N, 21, 3) keypoints in U (palm joint dropped)."""
    joints = np.delete(np.asarray(skeletons, np.float64), PALM_JOINT, axis=1)
    return joints @ R_UC.T


def command_labels(n_gesture: int, n_rest: int, dim: int, sign: int, ramp_frames: int) -> np.ndarray:
    """(n_rest + n_gesture + n_rest, 6) labels: the command's twist over the gesture, ramped, zero at rest."""
    env = np.ones(n_gesture)
    r = min(int(ramp_frames), n_gesture // 2)
    if r > 0:
        up = np.arange(1, r + 1) / (r + 1)
        env[:r] = up
        env[n_gesture - r:] = up[::-1]
    magnitude = TRANSLATION_M_S if dim < 3 else ROTATION_RAD_S
    y = np.zeros((n_gesture + 2 * n_rest, 6))
    y[n_rest:n_rest + n_gesture, dim] = sign * magnitude * env
    return y


def with_rest(keypoints: np.ndarray, n_rest: int, noise: np.ndarray | None = None,
              rng: np.random.Generator | None = None) -> np.ndarray:
    """The first frame held for n_rest frames before, the last after; with `noise` (M, 21, 3), each
    held run plus M's successive offsets from a point drawn by `rng`."""
    before, after = np.repeat(keypoints[:1], n_rest, 0), np.repeat(keypoints[-1:], n_rest, 0)
    if noise is not None and len(noise) and n_rest:
        for held in (before, after):
            held += noise[(int(rng.integers(len(noise))) + np.arange(n_rest)) % len(noise)]
    return np.concatenate([before, keypoints, after])


def rest_noise_of(keypoints: Iterable[np.ndarray]) -> np.ndarray:
    """(M, 21, 3) a person's tracking jitter where their hand hardly moves, over their sequences'
    keypoints (each (T, 21, 3) in U, in turn)."""
    from rtcohand_drake.data.hand_features import slow_noise

    parts = []
    for kp in keypoints:
        noise, slow = slow_noise(kp, FPS)
        parts.append(noise[slow])
    noise = np.concatenate(parts) if parts else np.zeros((0, 21, 3))
    return noise[np.all(np.isfinite(noise), axis=(1, 2))]


def command_map(mapping: str, variants: Sequence[tuple[int, int]], subject: int, seed: int
                ) -> dict[str, tuple[int, int]]:
    """Command name -> variant for one person (module docstring); only variants the person recorded."""
    if mapping in FIXED_MAPS:
        return {c: v for c, v in FIXED_MAPS[mapping].items() if v in set(variants)}
    if mapping != "custom":
        raise InputError(f"unknown mapping {mapping!r} (expected one of {', '.join(MAPPINGS)})")
    pool = sorted(set(variants))
    rng = np.random.default_rng([int(seed), int(subject)])
    picked = rng.choice(len(pool), size=min(len(COMMAND_NAMES), len(pool)), replace=False)
    return {c: pool[int(i)] for c, i in zip(COMMAND_NAMES, picked)}


def person_clips(sequences: Sequence[Sequence17], mapping: dict[str, tuple[int, int]], user: str, group: str,
                 rest_s: float, ramp_s: float, rest_noise: bool = False,
                 rng: np.random.Generator | None = None, held_out: int = 1) -> list[Clip]:
    """One person's clips: each mapped variant's repetitions, the last `held_out` of them held out (split
    "test"; the first is always context);
    with `rest_noise`, the rests carry the person's jitter (`rest_noise_of` over their mapped
    sequences in order, `with_rest`), drawn by `rng`."""
    n_rest = int(round(rest_s * FPS))
    ramp = int(round(ramp_s * FPS))
    mapped = [q for q in sequences if q.variant in set(mapping.values())]
    skeletons = {q.path: to_user_frame(read_skeletons(q.path)) for q in mapped}  # each file read once
    noise = rest_noise_of(skeletons[q.path] for q in mapped) if rest_noise else None
    clips = []
    for name, variant in mapping.items():
        dim, sign = COMMANDS[COMMAND_NAMES.index(name)]
        reps = sorted((q for q in sequences if q.variant == variant), key=lambda q: q.essai)
        for i, q in enumerate(reps):
            kp = skeletons[q.path]
            split = "test" if i >= max(1, len(reps) - held_out) else "train"
            g, f = variant
            clips.append(Clip(
                user=user, clip_id=f"g{g:02d}f{f}e{q.essai:02d}", group=group, split=split,
                active_dims=np.array([dim]), fps=FPS, keypoints=with_rest(kp, n_rest, noise, rng).astype(np.float32),
                object_velocity=command_labels(len(kp), n_rest, dim, sign, ramp).astype(np.float32),
                description=f"{GESTURES[g - 1]}, {FINGERS[f - 1]}, repetition {q.essai} -> {name}"))
    return sorted(clips, key=lambda c: c.clip_id)


def import_shrec17(root: Path, out: Path, mapping: str = "natural", subjects: Sequence[int] | None = None,
                   seed: int = 0, group: str = "out-sample", rest_s: float = 0.5, ramp_s: float = 0.2,
                   progress: bool = True, rest_noise: bool = False, held_out: int = 1) -> dict:
    """Write `out` from the dataset under `root`; returns a summary (people, clips, held out)."""
    if mapping not in MAPPINGS:
        raise InputError(f"unknown mapping {mapping!r} (expected one of {', '.join(MAPPINGS)})")
    if not (rest_s >= 0 and ramp_s >= 0):
        raise InputError(f"--rest-s and --ramp-s must be >= 0, got {rest_s}, {ramp_s}")
    if held_out < 1:
        raise InputError(f"--held-out must be at least 1, got {held_out}")
    sequences = find_sequences(root)
    present = sorted({q.subject for q in sequences})
    wanted = present if not subjects else [int(s) for s in subjects]
    missing = [s for s in wanted if s not in present]
    if missing:
        raise InputError(f"{root}: no sequences of subject(s) {', '.join(map(str, missing))} "
                         f"(found {', '.join(map(str, present))})")
    clips, maps = [], {}
    try:
        from tqdm import tqdm
        iterator = tqdm(wanted, desc="people", unit="person", disable=None if progress else True)  # None: tty only
    except ImportError:  # tqdm is a dependency; this keeps the importer usable without it
        iterator = wanted
    for s in iterator:
        own = [q for q in sequences if q.subject == s]
        user = f"s{s:02d}"
        cmap = command_map(mapping, [q.variant for q in own], s, seed)
        maps[user] = {c: f"G{g}F{f}" for c, (g, f) in cmap.items()}
        clips.extend(person_clips(own, cmap, user, group, rest_s, ramp_s, rest_noise,
                                  np.random.default_rng([int(seed), int(s), 1]), held_out))
    meta = {"source": "SHREC'17 track, 3D hand gesture skeletons (De Smedt et al., 3DOR 2017)",
            "mapping": mapping, "seed": int(seed), "rest_s": rest_s, "ramp_s": ramp_s, "fps": FPS,
            "rest": ("the held frames plus the person's own tracking jitter (--rest-noise)" if rest_noise
                     else "the first and last frames held still"),
            "translation_m_s": TRANSLATION_M_S, "rotation_rad_s": ROTATION_RAD_S,
            "axis_map": "X_U = x, Y_U = -z, Z_U = y (camera x right, y up, z depth toward the person)",
            "held_out": ("the last repetition of each mapped variant (split test); the others are context (train)"
                         if held_out == 1 else
                         f"the last {held_out} repetitions of each mapped variant, the first always context "
                         f"(split test); the others are context (train)")}
    if not clips:
        raise InputError(f"{root}: no labelled gesture of {', '.join(f's{s:02d}' for s in wanted) or 'any subject'} "
                         "could be read (no usable skeleton sequence); nothing written")
    write_dataset(out, clips, root_attrs={"import": json.dumps(meta)},
                  user_attrs={u: {"command_map": json.dumps(m)} for u, m in maps.items()})
    return {"people": len(wanted), "clips": len(clips), "held_out": sum(c.split == "test" for c in clips),
            "commands": {u: len(m) for u, m in maps.items()}}


def make_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m rtcohand_drake.data.import_shrec17", description=__doc__.splitlines()[0])
    p.add_argument("--root", required=True, type=Path, help="the dataset's folder (holds gesture_1 .. gesture_14)")
    p.add_argument("--out", required=True, type=Path, help="the gesture dataset file to write (.h5)")
    p.add_argument("--mapping", choices=MAPPINGS, default="natural", help="who commands what: natural (one fixed map, one motion in two postures), whole-hand (one fixed "
                        "map, every gesture with the whole hand) or custom (12 variants drawn per person); default natural")
    p.add_argument("--subjects", type=int, nargs="+", default=None, help="subject numbers (default: all found)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the custom maps")
    p.add_argument("--group", choices=("out-sample", "in-sample"), default="out-sample",
                   help="the users' group in the file (default out-sample)")
    p.add_argument("--rest-s", type=float, default=0.5, help="still hand before and after each gesture, s")
    p.add_argument("--ramp-s", type=float, default=0.2, help="label ramp at each end of the gesture, s")
    p.add_argument("--rest-noise", action="store_true",
                   help="rest with the person's own tracking jitter, as a tracked hand does (default: held still)")
    p.add_argument("--held-out", type=int, default=1, metavar="N",
                   help="hold out each variant's last N repetitions (split test; the first always stays context); "
                        "default 1")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    summary = import_shrec17(args.root, args.out, args.mapping, args.subjects, args.seed, args.group,
                             args.rest_s, args.ramp_s, rest_noise=args.rest_noise, held_out=args.held_out)
    print(f"wrote {args.out}: {summary['people']} people, {summary['clips']} clips, "
          f"{summary['held_out']} held out ({args.mapping} map)")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.data.import_shrec17"))


if __name__ == "__main__":
    entry_point()
