"""The gesture dataset file (docs/interfaces.md, the gesture dataset file): write, read and validate, and policy-rate clips.

Layout (HDF5)::

    /                         attrs: format = "rtcohand-gestures", version = 1
    /users/<user_id>          attrs: group = "in-sample" | "out-sample"
    /users/<user_id>/clips/<clip_id>
        attrs:    fps (float >= 5), active_dims (int array), split ("train"|"test"|"none")
        datasets: keypoints (N, 21, 3) float32 [NaN frame = hand lost],
                  object_velocity (N, 6) float32 (optional),
                  object_pose (N, 7) float32 (optional),
                  timestamps (N,) float64 (optional, else i / fps)

Optional extensions written here and ignored by readers that do not know them:
a clip attribute ``description`` (the gestures the clip shows, as text) and a
root attribute ``generator`` (the generator's configuration, JSON).

Every problem a reader finds raises :class:`DatasetError`, whose text is one
line: ``<file>: clip <user>/<clip>: <problem>`` (or ``<file>: <problem>`` for
problems of the file itself).
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np

from rtcohand_drake.errors import InputError
from rtcohand_drake.data.hand_features import FEATURE_DIM, frame_times, hand_features, path_shape_features, resample

FORMAT = "rtcohand-gestures"
VERSION = 1
DIMENSIONS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
GROUPS = ("in-sample", "out-sample")
SPLITS = ("train", "test", "none")
MIN_FPS = 5.0


class DatasetError(InputError):
    """A dataset file breaks the contract. ``str(err)`` is one line naming file, clip and problem."""

    def __init__(self, path: str | os.PathLike, problem: str, clip: str | None = None):
        self.path = str(path)
        self.clip = clip
        self.problem = " ".join(str(problem).split())
        where = f"{self.path}: clip {clip}: " if clip else f"{self.path}: "
        super().__init__(where + self.problem)


@dataclass(frozen=True, eq=False)
class Clip:
    """One recorded clip at its own frame rate, as stored in the file."""

    user: str
    clip_id: str
    group: str
    split: str
    active_dims: np.ndarray  # int, indices into DIMENSIONS
    fps: float
    keypoints: np.ndarray  # (N, 21, 3) float32, metres, user frame; NaN frame = hand lost
    object_velocity: np.ndarray | None = None  # (N, 6) float32, m/s and rad/s, user frame
    object_pose: np.ndarray | None = None  # (N, 7) float32, [x y z qw qx qy qz]
    timestamps: np.ndarray | None = None  # (N,) float64, seconds
    description: str = ""

    @property
    def name(self) -> str:
        return f"{self.user}/{self.clip_id}"

    @property
    def num_frames(self) -> int:
        return int(self.keypoints.shape[0])

    @property
    def times(self) -> np.ndarray:
        return frame_times(self.num_frames, self.fps, self.timestamps)


@dataclass(frozen=True, eq=False)
class PolicyClip:
    """A clip at the policy rate: features, validity and labels on the same sample times."""

    user: str
    clip_id: str
    group: str
    split: str
    active_dims: np.ndarray  # int
    features: np.ndarray  # (T, 36) float32; (T, 36 + PATH_SHAPE_DIM) with `to_policy_clip(path_shape=True)`
    valid: np.ndarray  # (T,) bool
    labels: np.ndarray | None  # (T, 6) float32, or None for an unlabelled stream
    rate_hz: float = 10.0

    @property
    def name(self) -> str:
        return f"{self.user}/{self.clip_id}"

    def __len__(self) -> int:
        return int(self.features.shape[0])


# --------------------------------------------------------------------------- writing


def write_dataset(path: str | os.PathLike, clips: Iterable[Clip], generator: str | None = None,
                  root_attrs: dict[str, str] | None = None, user_attrs: dict[str, dict[str, str]] | None = None) -> None:
    """Write clips to ``path`` atomically (a temporary file in the same folder, then a rename).

    ``generator`` (optional) is stored as the root attribute ``generator``; ``root_attrs`` and
    ``user_attrs`` (user -> attributes) add more text attributes (readers ignore them).
    """
    import h5py

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["version"] = VERSION
            if generator is not None:
                f.attrs["generator"] = generator
            for key, value in (root_attrs or {}).items():
                f.attrs[key] = value
            users = f.create_group("users")
            for clip in clips:
                _check_clip_for_writing(path, clip)
                if clip.user not in users:
                    g = users.create_group(clip.user)
                    g.attrs["group"] = clip.group
                    for key, value in (user_attrs or {}).get(clip.user, {}).items():
                        g.attrs[key] = value
                    g.create_group("clips")
                ug = users[clip.user]
                if ug.attrs["group"] != clip.group:
                    raise DatasetError(path, f"user is both {ug.attrs['group']} and {clip.group}", clip.name)
                cg = ug["clips"].create_group(clip.clip_id)
                cg.attrs["fps"] = float(clip.fps)
                cg.attrs["active_dims"] = np.asarray(clip.active_dims, dtype=np.int64).reshape(-1)
                cg.attrs["split"] = clip.split
                if clip.description:
                    cg.attrs["description"] = clip.description
                cg.create_dataset("keypoints", data=np.asarray(clip.keypoints, dtype=np.float32))
                if clip.object_velocity is not None:
                    cg.create_dataset("object_velocity", data=np.asarray(clip.object_velocity, dtype=np.float32))
                if clip.object_pose is not None:
                    cg.create_dataset("object_pose", data=np.asarray(clip.object_pose, dtype=np.float32))
                if clip.timestamps is not None:
                    cg.create_dataset("timestamps", data=np.asarray(clip.timestamps, dtype=np.float64))
        give_usual_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def give_usual_mode(path) -> None:
    """Gives a file the mode a plain open() would (0666 less the umask).

    The atomic writers start from `tempfile.mkstemp`, which makes the file private (0600);
    renamed into place as it is, a dataset or run log could not be read by another user."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def _check_clip_for_writing(path: Path, clip: Clip) -> None:
    problem = _clip_problem(
        clip.group, clip.split, clip.fps, np.asarray(clip.active_dims), np.asarray(clip.keypoints),
        clip.object_velocity, clip.object_pose, clip.timestamps,
    )
    if problem:
        raise DatasetError(path, problem, clip.name)


# --------------------------------------------------------------------------- reading


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return _text(value.item())
    return str(value)


def _clip_problem(group, split, fps, active_dims, keypoints, velocity, pose, timestamps) -> str | None:
    """The first contract problem of a clip's content, or None."""
    if group not in GROUPS:
        return f"user group must be one of {', '.join(GROUPS)}, got {group!r}"
    if split not in SPLITS:
        return f"split must be one of {', '.join(SPLITS)}, got {split!r}"
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        return f"fps must be a number, got {fps!r}"
    if not np.isfinite(fps) or fps < MIN_FPS:
        return f"fps must be a finite number >= {MIN_FPS:g}, got {fps!r}"
    if not np.issubdtype(active_dims.dtype, np.integer) or active_dims.ndim != 1:
        return f"active_dims must be a 1-D int array, got {active_dims.dtype} shape {active_dims.shape}"
    if active_dims.size and (active_dims.min() < 0 or active_dims.max() > 5):
        return f"active_dims must index [Tx, Ty, Tz, Rx, Ry, Rz] (0..5), got {active_dims.tolist()}"
    if np.unique(active_dims).size != active_dims.size:
        return f"active_dims has repeated entries: {active_dims.tolist()}"
    if not np.issubdtype(keypoints.dtype, np.floating):
        return f"keypoints must be float32, got {keypoints.dtype}"
    if keypoints.ndim != 3 or keypoints.shape[1:] != (21, 3) or keypoints.shape[0] < 1:
        return f"keypoints must have shape (N, 21, 3) with N >= 1, got {keypoints.shape}"
    n = keypoints.shape[0]
    if np.isinf(keypoints).any():
        return "keypoints hold infinite values"
    seen = np.isfinite(keypoints).all(axis=(1, 2))
    partial = ~seen & ~np.isnan(keypoints).all(axis=(1, 2))
    if partial.any():
        return f"keypoints frame {int(np.flatnonzero(partial)[0])} is partly NaN (a lost hand is an all-NaN frame)"
    for name, arr, width in (("object_velocity", velocity, 6), ("object_pose", pose, 7)):
        if arr is None:
            continue
        arr = np.asarray(arr)
        if not np.issubdtype(arr.dtype, np.floating):
            return f"{name} must be float32, got {arr.dtype}"
        if arr.shape != (n, width):
            return f"{name} must have shape ({n}, {width}), got {arr.shape}"
        if not np.isfinite(arr).all():
            return f"{name} holds non-finite values"
    if timestamps is not None:
        ts = np.asarray(timestamps)
        if not np.issubdtype(ts.dtype, np.floating):
            return f"timestamps must be float64, got {ts.dtype}"
        if ts.shape != (n,):
            return f"timestamps must have shape ({n},), got {ts.shape}"
        if not np.isfinite(ts).all():
            return "timestamps hold non-finite values"
        if n > 1 and not (np.diff(ts) > 0).all():
            return "timestamps must increase strictly"
    return None


def is_generated(path: str | os.PathLike) -> bool:
    """True for a dataset file of generated (simulated) people: its root carries the generator's
    settings (`generator`). A recording, an import of recorded people, or a file that cannot be read
    is not (reading it reports the problem)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return "generator" in f.attrs
    except (OSError, KeyError, RuntimeError, TypeError, ValueError):
        return False


def read_dataset(path: str | os.PathLike) -> list[Clip]:
    """All clips of a dataset file, validated against docs/interfaces.md (the gesture dataset file), in user then clip name order.

    Raises :class:`DatasetError` (one line: file, clip, problem) for any breach:
    unreadable or truncated file, unknown format/version, missing group or
    attribute, wrong shape or dtype, non-finite label.
    """
    import h5py

    path = Path(path)
    if not path.exists():
        raise DatasetError(path, "no such file")
    if path.is_dir():
        raise DatasetError(path, "is a folder, not a dataset file")
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise DatasetError(path, f"cannot be read as HDF5 (truncated or not a dataset file): {err}") from None
    try:
        with f:
            return _read_open_file(path, f)
    except DatasetError:
        raise
    except (OSError, KeyError, RuntimeError, TypeError, ValueError) as err:
        # h5py raises these for damaged objects inside a file that opened.
        raise DatasetError(path, f"damaged file: {type(err).__name__}: {err}") from None


def _read_open_file(path: Path, f) -> list[Clip]:
    import h5py

    fmt = _text(f.attrs["format"]) if "format" in f.attrs else None
    if fmt is None:
        raise DatasetError(path, "missing root attribute 'format'")
    if fmt != FORMAT:
        raise DatasetError(path, f"unknown format {fmt!r} (expected {FORMAT!r})")
    if "version" not in f.attrs:
        raise DatasetError(path, "missing root attribute 'version'")
    try:
        version = int(np.asarray(f.attrs["version"]).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        raise DatasetError(path, f"version must be an integer, got {f.attrs['version']!r}") from None
    if version != VERSION:
        raise DatasetError(path, f"unknown version {version} (expected {VERSION})")
    if "users" not in f or not isinstance(f["users"], h5py.Group):
        raise DatasetError(path, "missing group '/users'")
    clips: list[Clip] = []
    for user in sorted(f["users"].keys()):
        ug = f["users"][user]
        if not isinstance(ug, h5py.Group):
            raise DatasetError(path, f"/users/{user} is not a group")
        if "group" not in ug.attrs:
            raise DatasetError(path, f"user {user}: missing attribute 'group'")
        group = _text(ug.attrs["group"])
        if group not in GROUPS:
            raise DatasetError(path, f"user {user}: group must be one of {', '.join(GROUPS)}, got {group!r}")
        if "clips" not in ug or not isinstance(ug["clips"], h5py.Group):
            raise DatasetError(path, f"user {user}: missing group 'clips'")
        for clip_id in sorted(ug["clips"].keys()):
            clips.append(_read_clip(path, user, group, clip_id, ug["clips"][clip_id]))
    return clips


def _read_clip(path: Path, user: str, group: str, clip_id: str, cg) -> Clip:
    import h5py

    name = f"{user}/{clip_id}"
    if not isinstance(cg, h5py.Group):
        raise DatasetError(path, "is not a group", name)
    for attr in ("fps", "active_dims", "split"):
        if attr not in cg.attrs:
            raise DatasetError(path, f"missing attribute '{attr}'", name)
    if "keypoints" not in cg:
        raise DatasetError(path, "missing dataset 'keypoints'", name)

    def dataset(key):
        if key not in cg:
            return None
        obj = cg[key]
        if not isinstance(obj, h5py.Dataset):
            raise DatasetError(path, f"'{key}' is not a dataset", name)
        try:
            return obj[()]
        except (OSError, RuntimeError, ValueError) as err:
            raise DatasetError(path, f"cannot read '{key}' (damaged file?): {err}", name) from None

    fps_raw = np.asarray(cg.attrs["fps"])
    if fps_raw.size != 1 or not np.issubdtype(fps_raw.dtype, np.number):
        raise DatasetError(path, f"fps must be a number, got {cg.attrs['fps']!r}", name)
    fps = float(fps_raw.reshape(-1)[0])
    active = np.asarray(cg.attrs["active_dims"])
    if active.ndim == 0:
        active = active.reshape(1)
    if active.size == 0:
        active = np.zeros(0, dtype=np.int64)
    split = _text(cg.attrs["split"])
    keypoints = dataset("keypoints")
    velocity = dataset("object_velocity")
    pose = dataset("object_pose")
    timestamps = dataset("timestamps")
    problem = _clip_problem(group, split, fps, active, np.asarray(keypoints), velocity, pose, timestamps)
    if problem:
        raise DatasetError(path, problem, name)
    return Clip(
        user=user,
        clip_id=clip_id,
        group=group,
        split=split,
        active_dims=active.astype(np.int64),
        fps=fps,
        keypoints=np.asarray(keypoints, dtype=np.float32),
        object_velocity=None if velocity is None else np.asarray(velocity, dtype=np.float32),
        object_pose=None if pose is None else np.asarray(pose, dtype=np.float32),
        timestamps=None if timestamps is None else np.asarray(timestamps, dtype=np.float64),
        description=_text(cg.attrs["description"]) if "description" in cg.attrs else "",
    )


# --------------------------------------------------------------------------- policy rate


def to_policy_clip(clip: Clip, rate_hz: float = 10.0, path_shape: bool = False) -> PolicyClip:
    """Features and labels of a clip at the policy rate, on the same sample times.

    With `path_shape` the features are the 36 hand-part velocities followed by the hand's path and
    shape (`hand_features.path_shape_features`), the input of a policy file that reads them."""
    features, valid = hand_features(clip.keypoints, clip.fps, rate_hz, clip.timestamps)
    if path_shape:
        features = np.hstack([features, path_shape_features(clip.keypoints, clip.fps, rate_hz, clip.timestamps)])
    labels = None
    if clip.object_velocity is not None:
        labels, _ = resample(clip.object_velocity.astype(np.float64), clip.times, rate_hz)
        labels = labels.astype(np.float32)
    return PolicyClip(
        user=clip.user,
        clip_id=clip.clip_id,
        group=clip.group,
        split=clip.split,
        active_dims=clip.active_dims,
        features=features,
        valid=valid,
        labels=labels,
        rate_hz=float(rate_hz),
    )


def load_policy_clips(path: str | os.PathLike, rate_hz: float = 10.0, path_shape: bool = False) -> list[PolicyClip]:
    """Read and validate a dataset file, then convert every clip to the policy rate (`to_policy_clip`)."""
    return [to_policy_clip(c, rate_hz, path_shape) for c in read_dataset(path)]


def find_clips(clips: Iterable, spec: str) -> list:
    """Clips named by ``USER/CLIP`` (one clip) or ``USER`` (all of that user's clips)."""
    clips = list(clips)
    if "/" in spec:
        user, clip_id = spec.split("/", 1)
        return [c for c in clips if c.user == user and c.clip_id == clip_id]
    return [c for c in clips if c.user == spec]


def missing_motions(pieces, share: float = 0.25, min_steps: int = 3) -> list[str]:
    """The motions (Tx+ ... Rz-) a context holds no example of.

    A motion counts as present when at least `min_steps` context steps have a label along it
    (that dimension, that sign) of at least `share` of the largest label of the same half
    (linear or angular) anywhere in the context. The policy's read has little data behind a
    missing motion, so a gesture for it can be read large and in any direction.
    """
    labels = np.concatenate([np.asarray(y, np.float64).reshape(-1, 6) for _, y in pieces])
    labels = np.nan_to_num(labels, nan=0.0, posinf=0.0, neginf=0.0)
    missing = []
    for half in (slice(0, 3), slice(3, 6)):
        level = share * float(np.abs(labels[:, half]).max())
        for d in range(half.start, half.stop):
            for sign, mark in ((1.0, "+"), (-1.0, "-")):
                if level <= 0.0 or int(np.count_nonzero(sign * labels[:, d] >= level)) < min_steps:
                    missing.append(DIMENSIONS[d] + mark)
    return missing


def lost_hand_share(pieces) -> float:
    """The share of a context's labelled steps (any label nonzero) that show no hand motion at all: every
    one of the 36 hand-part velocities zero or not finite, as where the tracker lost the hand (a tracked
    hand never holds exactly still); 0 for a context with no labelled step. The policy reads such a step
    as no motion, so a context lost in most of its gestures teaches it little."""
    lost = labelled = 0
    for x, y in pieces:
        on = np.abs(np.nan_to_num(np.asarray(y, np.float64).reshape(len(x), -1))).sum(1) > 0
        gone = ~(np.nan_to_num(np.asarray(x, np.float64)[:, :FEATURE_DIM], nan=0.0, posinf=0.0, neginf=0.0)
                 != 0).any(1)
        lost += int(np.count_nonzero(gone & on))
        labelled += int(np.count_nonzero(on))
    return lost / labelled if labelled else 0.0


def _some(names: list[str], shown: int = 8) -> str:
    """The first `shown` names, and how many more there are, for a one-line error."""
    more = f", ... and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


def as_paths(paths) -> list:
    """One path (str or path-like) or several, as a list."""
    return [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)


def user_policy_clips(paths, user: str | None, rate_hz: float, path_shape: bool = False):
    """One user's labelled clips at the policy rate, from one dataset file or several read together
    (`--context-file A.h5 B.h5`: a first session and a re-recording, say), and the user.

    `user` may be None when the files hold one user between them. Each file must hold labelled
    clips, and the user's among them; an error names the file.
    """
    paths = as_paths(paths)
    per_file = []
    for path in paths:
        clips = [c for c in load_policy_clips(path, rate_hz, path_shape) if c.labels is not None]
        if not clips:
            raise InputError(f"{path}: no labelled clips to use as context")
        per_file.append((path, clips))
    if user is None:
        users = sorted({c.user for _, clips in per_file for c in clips})
        if len(users) > 1:
            where = " and ".join(map(str, paths))
            raise InputError(f"{where}: {'hold' if len(paths) > 1 else 'holds'} {len(users)} users; choose one "
                             f"with --context-user ({_some(users)})")
        user = users[0]
    mine = []
    for path, clips in per_file:
        own = [c for c in clips if c.user == user]
        if not own:
            raise InputError(f"{path}: user {user!r} has no labelled clips to use as context "
                             f"(users: {_some(sorted({c.user for c in clips}))})")
        mine += own
    return mine, user


def recorder_protocol(path) -> tuple[str | None, dict]:
    """(the file's `label_source`, the recorder's `protocol`) of a dataset file (docs/interfaces.md, the
    recorder's attributes); the protocol is {} for a file the recorder did not write. A `recorder`
    attribute that is not the recorder's JSON is a `DatasetError`."""
    import h5py

    with h5py.File(path, "r") as f:
        source, recorder = f.attrs.get("label_source"), f.attrs.get("recorder")
    if recorder is None:
        return source, {}
    try:
        protocol = json.loads(recorder).get("protocol", {})
    except (TypeError, ValueError, AttributeError):
        protocol = None
    if not isinstance(protocol, dict):
        raise DatasetError(f"{path}: root attribute 'recorder' is not the recorder's JSON")
    return source, protocol


def label_lag_s(paths) -> float:
    """How late the labels of these dataset files follow the gesture, s (the largest over the files): a
    recorder session's cue labels are placed `label_delay_s` after the cue, of which the protocol's
    `label_lag_s` is after the person's gesture (docs/interfaces.md, the recorder's attributes); 0 for
    any other file (generated people's handler labels, imported recordings, ArUco labels)."""
    lag = 0.0
    for path in as_paths(paths):
        source, protocol = recorder_protocol(path)
        if source != "cue":
            continue
        try:
            lag = max(lag, float(protocol.get("label_lag_s", 0.0)))
        except (TypeError, ValueError):
            raise DatasetError(f"{path}: root attribute 'recorder' is not the recorder's JSON") from None
    return lag


def context_pieces(paths, user: str | None, rate_hz: float, exclude=(), path_shape: bool = False):
    """A user's own labelled clips from a dataset file or several (`user_policy_clips`), as
    (features, labels) pieces, and the user.

    Clips named in `exclude` are left out; `path_shape` appends the hand's path and shape to the
    features (`to_policy_clip`).
    """
    clips, user = user_policy_clips(paths, user, rate_hz, path_shape)
    pieces = [(c.features, c.labels) for c in clips if c.name not in exclude]
    if not pieces:
        raise InputError(f"{' and '.join(map(str, as_paths(paths)))}: user {user!r} has no labelled clips left "
                         "to use as context")
    return pieces, user
