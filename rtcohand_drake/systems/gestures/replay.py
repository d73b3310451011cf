"""`ReplayGestureSource`: plays dataset clips (docs/interfaces.md, the gesture dataset file)
back to back, with exactly the features the offline pipeline computes for them.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from rtcohand_drake.data.hand_features import join_recordings
from rtcohand_drake.errors import InputError
from rtcohand_drake.interfaces import (FEATURE_DIM, GESTURE_FEATURES, GESTURE_STATUS, GESTURE_STATUS_DIM,
                                       INTENDED_TWIST, KEYPOINTS, KEYPOINTS_DIM, TWIST_DIM)
from rtcohand_drake.systems.gestures.base import NAN_HAND


class ReplayGestureSource(LeafSystem):
    """Replays clips at the policy rate (features computed offline, exactly as in training).

    `clips` are `PolicyClip`s; `skeletons` (optional) are per-clip keypoint
    arrays resampled at the policy rate, for drawing and for a policy that reads the hand's path
    and shape; each clip's skeleton is moved to start where the one before ended
    (`hand_features.join_recordings`), so the hand does not jump from one clip to the next (the
    features, velocities, are each clip's own). After the last clip the
    source reports an invalid gesture (the supervisor's watchdog then stops the arm).

    When every clip is labelled, the output `intended_twist` is the label of the frame being played
    (zero after the last clip): the run logs it, and `analysis.replay_read` scores the policy's read
    of the stream against it.
    """

    def __init__(self, clips: Sequence, rate_hz: float = 10.0, skeletons: Sequence[np.ndarray] | None = None):
        super().__init__()
        if not clips:
            raise ValueError("ReplayGestureSource needs at least one clip")
        self._rate = rate_hz
        self._features = np.concatenate([c.features for c in clips]).astype(float)
        self._valid = np.concatenate([c.valid for c in clips]).astype(float)
        self._labels = (np.concatenate([c.labels for c in clips]) if all(c.labels is not None for c in clips)
                        else None)
        self.clip_starts = np.cumsum([0] + [len(c) for c in clips])[:-1] / rate_hz
        self.clip_names = [c.name for c in clips]
        self._skeletons = (np.concatenate([s.reshape(len(s), 63) for s in join_recordings(
            [np.asarray(s, float).reshape(len(s), 21, 3) for s in skeletons])]) if skeletons is not None else None)
        self.DeclareVectorOutputPort(GESTURE_FEATURES, FEATURE_DIM, self._calc_features)
        self.DeclareVectorOutputPort(GESTURE_STATUS, GESTURE_STATUS_DIM, self._calc_status)
        self.DeclareVectorOutputPort(KEYPOINTS, KEYPOINTS_DIM, self._calc_keypoints)
        if self._labels is not None:
            self.DeclareVectorOutputPort(INTENDED_TWIST, TWIST_DIM, self._calc_label)

    @property
    def end_time(self) -> float:
        return len(self._features) / self._rate

    @property
    def features(self) -> np.ndarray:
        return self._features

    @property
    def labels(self) -> np.ndarray | None:
        return self._labels

    def _index(self, context) -> int:
        return int(np.floor(context.get_time() * self._rate + 1e-6))

    def _calc_features(self, context, output: BasicVector):
        k = self._index(context)
        output.SetFromVector(self._features[k] if k < len(self._features) else np.zeros(36))

    def _calc_status(self, context, output: BasicVector):
        k = self._index(context)
        if k < len(self._features):
            output.SetFromVector([self._valid[k], k / self._rate])
        else:  # the stream has ended: no fresh gesture
            output.SetFromVector([0.0, (len(self._features) - 1) / self._rate])

    def _calc_label(self, context, output: BasicVector):
        k = self._index(context)
        output.SetFromVector(self._labels[k] if k < len(self._labels) else np.zeros(TWIST_DIM))

    def _calc_keypoints(self, context, output: BasicVector):
        k = self._index(context)
        if self._skeletons is not None and k < len(self._skeletons):
            output.SetFromVector(self._skeletons[k])
        else:
            output.SetFromVector(NAN_HAND.reshape(-1))


def from_options(options, scenario):
    """The `replay` source: `options.gesture_file`, optionally one clip or user (`options.clip`),
    optionally only the clips of one split (`options.split`: `test`, a person's held-out clips).

    Its default context is the replayed user's other labelled clips in the same file.
    """
    from rtcohand_drake.data.dataset import context_pieces, find_clips, read_dataset, to_policy_clip
    from rtcohand_drake.data.hand_features import resample
    from rtcohand_drake.systems.gestures.registry import GestureSetup

    path = options.gesture_file
    raw_all = sorted(read_dataset(path), key=lambda c: (c.user, c.clip_id))
    raw = raw_all
    if options.clip is not None:
        raw = find_clips(raw, options.clip)
        if not raw:
            raise InputError(f"{path}: no clip or user named {options.clip!r}")
    split = getattr(options, "split", None)
    if split is not None:
        raw = [c for c in raw if c.split == split]
        if not raw:
            raise InputError(f"{path}: no clip of split {split!r}" + (f" for {options.clip!r}" if options.clip else ""))
    rate = scenario.policy.rate_hz
    clips = [to_policy_clip(c, rate) for c in raw]
    skeletons = [resample(c.keypoints.reshape(len(c.keypoints), -1).astype(float), c.times, rate)[0] for c in raw]
    source = ReplayGestureSource(clips, rate, skeletons)
    users = sorted({c.user for c in raw})
    names = {c.name for c in clips}

    def default_context(path_shape: bool = False):
        if len(users) != 1:
            raise InputError(f"{path}: the replayed stream has {len(users)} users; "
                             "give their context with --context-file and --context-user")
        mine = [c for c in raw_all if c.user == users[0] and c.object_velocity is not None]
        replayed = {(c.user, c.clip_id) for c in raw}
        if mine and all((c.user, c.clip_id) in replayed for c in mine):
            raise InputError(f"{path}: all {len(mine)} labelled clips of user {users[0]!r} are being replayed, "
                             "so none is left as context; replay one clip (--clip USER/CLIP) or give the "
                             "context with --context-file PATH.h5 [--context-user USER]")
        return context_pieces(path, users[0], rate, exclude=names, path_shape=path_shape)[0]

    return GestureSetup(source, default_context, source.end_time)
