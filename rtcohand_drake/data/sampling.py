"""Context and target sampling for training and evaluation (CCHP paper, training and tests).

A *context* is a list of pieces ``(features (K, 36), labels (K, 6))`` at the
policy rate. The policy attends over every step of every piece, so a batch is
built by concatenating a context's pieces in time and padding:
:func:`collate_contexts` gives ``x_c (B, T, 36)``, ``y_c (B, T, 6)`` and a
``mask (B, T)`` that is True on real steps.

Training (:func:`sample_context`)
---------------------------------
For a target clip and a pool (the training clips):

1. Draw ``want_d = U < p_d`` and ``want_u = U < p_u``.
2. D+ candidates contain all of the target's active dimensions
   (``set(target) <= set(clip)``); D- candidates do not. U+ candidates belong
   to the target's user; U- candidates do not. The chosen clip is drawn
   uniformly from the candidates matching both wishes; if there are none the
   user wish is dropped, then the dimension wish, then any labelled clip of
   the pool is taken.
3. If the chosen clip is the target itself, only a slice ``[t0, t0 + K)`` of
   it is used, with ``K >= t_min`` and ``t0 + K <= p_cxt * len(target)``
   (K and t0 uniform over the allowed values; when ``p_cxt * len < t_min``
   the slice is the first ``floor(p_cxt * len)`` steps, at least one).
4. ``n_user`` more clips (default 0) are drawn uniformly, without
   replacement, from the target user's labelled pool clips other than the
   target and the chosen clip (fewer if the user has fewer). This matches
   deployment, where the context is the user's own clips.
5. ``n_random`` more clips are drawn uniformly, without replacement, from the
   labelled pool clips other than the target and the clips already chosen.

Evaluation (:func:`evaluation_episodes`)
----------------------------------------
``D_train`` = labelled clips of in-sample users with split "train";
``D_test,in`` = labelled clips of in-sample users with split "test";
``D_test,out`` = labelled clips of out-sample users with split "test".
Each setting gives one episode per eligible target, in (user, clip) name
order; the context is one chosen clip followed by two random clips, all whole
clips from ``D_train``:

- ``D+U+``: target from D_test,in; chosen clip from D_train, same user, whose
  active dimensions contain all of the target's.
- ``D+U-``: as D+U+ but the chosen clip is from another user.
- ``D-U+``: chosen clip from the same user whose active dimensions do not
  contain all of the target's.
- ``D-U-``: chosen clip from another user, not containing the target's dimensions.
- ``Unseen``: target from D_test,out; chosen clip from D_train (necessarily
  other users) containing the target's active dimensions (any D_train clip if
  none does).
- ``Noisy``: the D+U+ episodes with Gaussian noise sigma_T = 0.05 m/s on the
  target's linear-velocity entries and sigma_R = 0.025 rad/s on its
  angular-velocity entries; the context stays clean.

Two more settings are not in the paper and not in the default six:

- ``Own``: the deployed setting. Target from D_test,out; the context is every
  other labelled clip of the target's user (all whole clips; for an
  out-sample user, the rest of their 72), no random clips. This is what the
  run CLI gives the policy for the built-in simulated person.
- ``Person``: the protocol for recorded people (`rtcohand_drake.data.import_shrec17`).
  Target: every labelled clip with split "test", of any user and group; the
  context is every labelled clip of the same user with split "train" (whole
  clips, no random clips). A user with no train clip gives no episode.

In every paper setting the two random clips are drawn uniformly from the D_train
clips other than the chosen one (any user). A target with no clip matching
its setting's rule for the chosen clip is left out (so a file with no
out-sample users gives no Unseen episodes, and a target whose pair of
dimensions never occurs in D_train has no D+ episode). All draws come from
``numpy.random.default_rng([seed, setting index])``: the same file and seed
give the same episodes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from rtcohand_drake.data.dataset import PolicyClip
from rtcohand_drake.data.hand_features import FEATURE_DIM, PARTS

SETTINGS = ("D+U+", "D+U-", "D-U+", "D-U-", "Unseen", "Noisy")
NOISY_SIGMA_T = 0.05  # m/s, on linear-velocity entries
NOISY_SIGMA_R = 0.025  # rad/s, on angular-velocity entries
OWN_SETTING = "Own"  # the deployed setting (module docstring); not one of the paper's six
PERSON_SETTING = "Person"  # recorded people: each user's held-out clips read with their own train clips
ALL_SETTINGS = SETTINGS + (OWN_SETTING, PERSON_SETTING)
EVAL_RANDOM_CLIPS = 2

Piece = tuple[np.ndarray, np.ndarray]  # (features (K, 36) float32, labels (K, 6) float32)

# Masks over the 36 feature entries: linear-velocity and angular-velocity entries.
LINEAR_ENTRIES = np.zeros(FEATURE_DIM, dtype=bool)
for _p in range(len(PARTS)):
    LINEAR_ENTRIES[6 * _p : 6 * _p + 3] = True
ANGULAR_ENTRIES = ~LINEAR_ENTRIES


def _dims(clip: PolicyClip) -> set[int]:
    return set(int(d) for d in np.asarray(clip.active_dims).reshape(-1))


def contains_dims(context: PolicyClip, target: PolicyClip) -> bool:
    """True when ``context``'s active dimensions include all of ``target``'s (the D+ rule)."""
    return _dims(target) <= _dims(context)


def _same(a: PolicyClip, b: PolicyClip) -> bool:
    return a.user == b.user and a.clip_id == b.clip_id


def _whole(clip: PolicyClip) -> Piece:
    return clip.features, clip.labels


def _target_slice(target: PolicyClip, rng: np.random.Generator, t_min: int, p_cxt: float) -> Piece:
    n = len(target)
    limit = int(np.floor(p_cxt * n))
    if limit < max(t_min, 1):
        k = max(limit, 1)
        return target.features[:k], target.labels[:k]
    k = int(rng.integers(t_min, limit + 1))
    t0 = int(rng.integers(0, limit - k + 1))
    return target.features[t0 : t0 + k], target.labels[t0 : t0 + k]


def sample_context(
    target: PolicyClip,
    pool: Sequence[PolicyClip],
    rng: np.random.Generator,
    p_d: float = 0.5,
    p_u: float = 0.5,
    n_random: int = 2,
    t_min: int = 10,
    p_cxt: float = 0.5,
    n_user: int = 0,
) -> list[Piece]:
    """Context pieces for one training target (rules in the module docstring)."""
    index = _pool_index(pool)
    labelled = index.labelled
    if not labelled:
        raise ValueError("the context pool holds no labelled clip")
    want_d = rng.random() < p_d
    want_u = rng.random() < p_u
    t_mask = _dims_mask(target)
    is_d = ((index.dims & t_mask) == t_mask) == want_d
    is_u = (index.users == target.user) == want_u
    chosen = None
    for keep in (is_d & is_u, is_d, np.ones(len(labelled), bool)):
        idx = np.flatnonzero(keep)
        if len(idx):
            chosen = labelled[idx[int(rng.integers(len(idx)))]]
            break
    assert chosen is not None
    if _same(chosen, target):
        if target.labels is None:
            raise ValueError(f"target {target.name} has no labels to use as context")
        pieces = [_target_slice(target, rng, t_min, p_cxt)]
    else:
        pieces = [_whole(chosen)]
    not_target = ~((index.users == target.user) & (index.clip_ids == target.clip_id))
    not_chosen = ~((index.users == chosen.user) & (index.clip_ids == chosen.clip_id))
    free = not_target & not_chosen
    if n_user > 0:
        own = np.flatnonzero(free & (index.users == target.user))
        if len(own):
            pick = own[rng.choice(len(own), size=min(n_user, len(own)), replace=False)]
            pieces.extend(_whole(labelled[int(i)]) for i in pick)
            free[pick] = False
    others = np.flatnonzero(free)
    if len(others) and n_random > 0:
        pick = rng.choice(len(others), size=min(n_random, len(others)), replace=False)
        pieces.extend(_whole(labelled[others[int(i)]]) for i in pick)
    return pieces


@dataclass
class _PoolIndex:
    """The labelled clips of a context pool with their users, clip ids and dimension masks as arrays."""

    labelled: list
    users: np.ndarray
    clip_ids: np.ndarray
    dims: np.ndarray  # bit d set: dimension d is active


def _dims_mask(clip: PolicyClip) -> int:
    return sum(1 << d for d in _dims(clip))


_POOL_INDEXES: dict[int, tuple[Sequence[PolicyClip], int, _PoolIndex]] = {}


def _pool_index(pool: Sequence[PolicyClip]) -> _PoolIndex:
    """The index of a pool, built once per pool object (training samples from the same pool every step)."""
    cached = _POOL_INDEXES.get(id(pool))
    if cached is not None and cached[0] is pool and cached[1] == len(pool):
        return cached[2]
    labelled = [c for c in pool if c.labels is not None]
    index = _PoolIndex(labelled, np.array([c.user for c in labelled], dtype=object),
                       np.array([c.clip_id for c in labelled], dtype=object),
                       np.array([_dims_mask(c) for c in labelled], dtype=np.int64))
    if len(_POOL_INDEXES) >= 8:
        _POOL_INDEXES.clear()
    _POOL_INDEXES[id(pool)] = (pool, len(pool), index)
    return index


@dataclass
class ContextSet:
    """A context as pieces; ``concat`` joins them in time (the policy attends over all steps)."""

    pieces: list[Piece] = field(default_factory=list)

    def __len__(self) -> int:
        return int(sum(p[0].shape[0] for p in self.pieces))

    def concat(self) -> Piece:
        if not self.pieces:
            return np.zeros((0, FEATURE_DIM), np.float32), np.zeros((0, 6), np.float32)
        x = np.concatenate([p[0] for p in self.pieces]).astype(np.float32, copy=False)
        y = np.concatenate([p[1] for p in self.pieces]).astype(np.float32, copy=False)
        return x, y


def pack_context(
    pieces: Sequence[Piece], max_len: int | None = None, drop_empty: bool = True, dtype=np.float32
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Context pieces [(features (T, F), labels (T, 6)), ...] as one padded batch (F = 36, or more for a
    policy that reads the hand's path and shape).

    Returns x_c (P, T, F), y_c (P, T, 6) and mask (P, T) bool (True on real
    steps): a row per piece, zero-padded to the longest (or cut to ``max_len``
    steps, keeping the first ones). Non-finite values (frames where the hand
    was not seen) become 0. ``drop_empty`` leaves out zero-length pieces and
    needs at least one piece left; the exported policy's `encode_context`
    takes the result as it is.
    """
    if drop_empty:
        pieces = [p for p in pieces if len(p[0])]
        if not pieces:
            raise ValueError("a context needs at least one non-empty labelled piece")
    T = max((len(x) for x, _ in pieces), default=0)
    if max_len is not None:
        T = min(T, max_len)
    width = pieces[0][0].shape[1] if pieces and np.ndim(pieces[0][0]) == 2 else FEATURE_DIM  # 36, or more (path_shape)
    x_c = np.zeros((len(pieces), T, width), dtype)
    y_c = np.zeros((len(pieces), T, 6), dtype)
    mask = np.zeros((len(pieces), T), bool)
    for b, (x, y) in enumerate(pieces):
        k = min(len(x), T)
        x_c[b, :k] = np.nan_to_num(np.asarray(x[:k], dtype), nan=0.0, posinf=0.0, neginf=0.0)
        y_c[b, :k] = np.nan_to_num(np.asarray(y[:k], dtype), nan=0.0, posinf=0.0, neginf=0.0)
        mask[b, :k] = True
    return x_c, y_c, mask


def collate_contexts(
    contexts: Sequence[Sequence[Piece] | ContextSet], max_len: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batch contexts: x_c (B, T, 36), y_c (B, T, 6), mask (B, T) bool (True on real steps).

    Each context's pieces are concatenated in time, then packed (`pack_context`).
    """
    joined = [(c if isinstance(c, ContextSet) else ContextSet(list(c))).concat() for c in contexts]
    return pack_context(joined, max_len=max_len, drop_empty=False)


def add_feature_noise(
    features: np.ndarray, sigma_t: float, sigma_r: float, rng: np.random.Generator
) -> np.ndarray:
    """Features plus N(0, sigma_t^2) on linear-velocity entries and N(0, sigma_r^2) on angular ones."""
    x = np.asarray(features, dtype=np.float32)
    if x.shape[-1] != FEATURE_DIM:
        raise ValueError(f"features must end in {FEATURE_DIM}, got {x.shape}")
    sigma = np.where(LINEAR_ENTRIES, sigma_t, sigma_r).astype(np.float64)
    return (x + rng.standard_normal(x.shape) * sigma).astype(np.float32)


@dataclass
class Episode:
    """One evaluation case: a target, its context pieces and the noise on the target input."""

    target: PolicyClip
    context: list[Piece]
    noise: tuple[float, float] = (0.0, 0.0)  # (sigma_T m/s, sigma_R rad/s) on target features
    target_features: np.ndarray | None = None  # the target input to use (noisy in "Noisy")
    setting: str = ""
    chosen: str = ""  # USER/CLIP of the chosen context clip

    def __post_init__(self) -> None:
        if self.target_features is None:
            self.target_features = self.target.features


def split_sets(clips: Sequence[PolicyClip]) -> tuple[list, list, list]:
    """(D_train, D_test_in, D_test_out) of labelled clips, in (user, clip) name order."""
    ordered = sorted((c for c in clips if c.labels is not None), key=lambda c: (c.user, c.clip_id))
    train = [c for c in ordered if c.group == "in-sample" and c.split == "train"]
    test_in = [c for c in ordered if c.group == "in-sample" and c.split == "test"]
    test_out = [c for c in ordered if c.group == "out-sample" and c.split == "test"]
    return train, test_in, test_out


_RULES = {
    # setting: (target set, D wish (True/False/None), U wish (True/False/None))
    "D+U+": ("in", True, True),
    "D+U-": ("in", True, False),
    "D-U+": ("in", False, True),
    "D-U-": ("in", False, False),
    "Unseen": ("out", True, None),
    "Noisy": ("in", True, True),
}


def evaluation_episodes(clips: Sequence[PolicyClip], setting: str, seed: int) -> list[Episode]:
    """The episodes of one evaluation setting (exact rules in the module docstring).

    Works on any contract-conforming file: settings with no eligible target
    (e.g. Unseen with no out-sample users) give an empty list.
    """
    if setting not in ALL_SETTINGS:
        raise ValueError(f"unknown setting {setting!r}; expected one of {', '.join(ALL_SETTINGS)}")
    rng = np.random.default_rng([int(seed), ALL_SETTINGS.index(setting)])
    train, test_in, test_out = split_sets(clips)
    if setting == PERSON_SETTING:
        ordered = sorted((c for c in clips if c.labels is not None), key=lambda c: (c.user, c.clip_id))
        context = {}
        for c in ordered:
            if c.split == "train":
                context.setdefault(c.user, []).append(_whole(c))
        return [Episode(target=t, context=list(context[t.user]), setting=setting)
                for t in ordered if t.split == "test" and t.user in context]
    if setting == OWN_SETTING:
        return [
            Episode(target=t, context=[_whole(c) for c in test_out if c.user == t.user and not _same(c, t)],
                    setting=setting, chosen="")
            for t in test_out
            if any(c.user == t.user and not _same(c, t) for c in test_out)
        ]
    targets_from, want_d, want_u = _RULES[setting]
    targets = test_in if targets_from == "in" else test_out
    noise = (NOISY_SIGMA_T, NOISY_SIGMA_R) if setting == "Noisy" else (0.0, 0.0)
    episodes: list[Episode] = []
    for target in targets:
        cands = [
            c
            for c in train
            if not _same(c, target)
            and (want_d is None or contains_dims(c, target) == want_d)
            and (want_u is None or (c.user == target.user) == want_u)
        ]
        if setting == "Unseen" and not cands:
            cands = [c for c in train if not _same(c, target)]
        if not cands:
            continue
        chosen = cands[int(rng.integers(len(cands)))]
        others = [c for c in train if not _same(c, chosen) and not _same(c, target)]
        pieces = [_whole(chosen)]
        if others:
            pick = rng.choice(len(others), size=min(EVAL_RANDOM_CLIPS, len(others)), replace=False)
            pieces.extend(_whole(others[int(i)]) for i in pick)
        x_t = target.features
        if noise != (0.0, 0.0):
            x_t = add_feature_noise(x_t, noise[0], noise[1], rng)
        episodes.append(
            Episode(target=target, context=pieces, noise=noise, target_features=x_t, setting=setting, chosen=chosen.name)
        )
    return episodes
