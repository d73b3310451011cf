"""How well the policy reads each of a user's gestures, from that user's own labelled clips.

    python -m rtcohand_drake.context_reading --context-file PATH.h5 [PATH.h5 ...] [--context-user USER]
        [--model PATH.pt] [--folds 6] [--rate-hz 10] [--no-progress]
    python -m rtcohand_drake.context_reading --user u10      # a built-in simulated user

Before a new person drives the arm, their labelled clips can tell how well
the policy will read them. The clips are split into `folds` groups; each group
is played through the exported policy (docs/interfaces.md, the exported policy) with the other groups as
context, exactly as the run diagram runs it (zero start state, own mean fed
back, z = the mean of q(z|C)). For each active dimension of each clip the
*reading gain* is the mean predicted twist on that dimension over the steps
where its label is above 30 % of its peak, divided by the label's mean there:
1 reads the gesture at its full size, 0.2 moves the part at a fifth of the
speed the person meant, a negative gain moves it the wrong way.

The table lists the 12 motions (dimension and sign) with the median gain of
their clips, the same gain for a ridge regression fitted on the same folds
(the fitted-to-the-person reference, the bar the policy must clear), and a verdict: `reads` (>= 0.5), `weak` (0.2 .. 0.5), `poor`
(< 0.2, or the wrong way). A poorly read gesture is worth re-recording or
replacing by a more distinct one before the session. A one-motion gesture
with fewer than three recordings among the clips is named too: a person's
read gains much from a second and third recording of each gesture. So is a
gesture the read moves along another motion while it is made (a third of
that motion's command or more, the median over its clips): to the read the
two gestures look alike, as a whole-hand and a one-finger turn can. The last lines give the
median gain over all clips and the held-out squared error of the output as a
share of commanding zero twist (the "Own" evaluation setting, in six folds),
for the policy and for the reference.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.errors import ArgumentParser, InputError, non_negative_int, positive_float, run_cli
from rtcohand_drake.record import DEFAULT_REPEATS

MOTION_NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
READS, WEAK = 0.5, 0.2  # verdict thresholds on the reading gain
# What a person can do about a motion the policy cannot read from their clips. Finger sweeps of a
# curled hand are the gestures no read of the hand data tells apart (docs/results/sweep/).
POOR_ADVICE = ("poorly read: {motions}. The arm will barely follow these gestures. Record a different "
               "gesture for them: a move or turn of the whole hand, or a sweep with the fingers "
               "extended (a spread or thumb sweep of a curled hand does not show its direction)")
# What a person can do about a motion the policy reads poorly although a read of the whole recent
# motion (the nearest-neighbour reference) reads it: the hand shows the gesture, but as a stroke or
# shape (out and back, a short flick) where the policy reads a motion held while the part should move.
STROKE_ADVICE = ("read by its shape but not by the policy: {motions}. These gestures are told apart by "
                 "the course of the stroke, and the policy reads the hand's motion while the part should "
                 "move: keep moving or turning the hand for as long as the part should, rather than "
                 "stroking out and back")
# The same, for a person who recorded strokes on purpose (`record --style stroke`): the policy reads
# the hand's motion while the part should move, which a stroke shows only while it lasts.
STROKE_STYLE_ADVICE = ("read by its shape but not by the policy: {motions}. You recorded these as strokes, "
                       "and the policy reads the hand's motion while the part should move, which a stroke "
                       "shows only while it lasts: record them again with the motion held "
                       "(python -m rtcohand_drake.record --style hold --only {only}), or make each stroke "
                       "last as long as the part should move")
ACTIVE_SHARE = 0.3  # steps where |label| exceeds this share of its peak count as the motion
# A person's read gains much from a second and third recording of each gesture (docs/real_people.md,
# section 6, "Recordings of each gesture in the context"); the recorder makes this many, and the check
# names the one-motion gestures with fewer.
RECORDINGS = DEFAULT_REPEATS
# A gesture is read as another when the read moves the part along that other motion by at least this share
# of the person's command on its axis (median over the gesture's clips, while it is made). On the 10 recorded
# development people it names one pair for 9 of their 30 person-maps (2 whole-hand, 3 natural, among them
# s04's Ry+ as Rz-, the map's whole-hand and one-finger turns, and 4 custom), and nothing for the 5
# out-sample simulated people of population 0.
CONFUSED_SHARE = 0.3
CONFUSED_ADVICE = ("read as another motion: {pairs}. While you make these gestures the arm also moves the "
                   "other way named: to the read, your two gestures look alike. Make one of each pair more "
                   "distinct (another motion of the hand, or another posture), or record more of both")
FEW_ADVICE = ("fewer than {n} recordings of: {motions}. The policy reads you from your own examples: from one "
              "recording of each gesture it read recorded people's held-out gestures at 0.69-0.79 of the error "
              "of commanding zero twist, from three at 0.50-0.69. Record these again "
              "(python -m rtcohand_drake.record --only {only}) and read both files as one context")


@dc.dataclass
class LabelledClip:
    """A clip at the policy rate: features (T, 36), labels (T, 6), its active dimensions."""

    name: str
    features: np.ndarray
    labels: np.ndarray
    active_dims: tuple[int, ...]
    split: str = "none"


@dc.dataclass
class ClipReading:
    name: str
    dim: int
    sign: int  # of the label on the active dimension
    gain: float  # mean prediction / mean label on the active steps


def motion_name(dim: int, sign: int) -> str:
    return MOTION_NAMES[dim] + ("+" if sign > 0 else "-")


def verdict(gain: float) -> str:
    return "reads" if gain >= READS else "weak" if gain >= WEAK else "poor"


def play_clip(module, features: np.ndarray, keys, values, z, correction_weight: float = 1.0,
              variances: list | None = None) -> np.ndarray:
    """The policy's output twists (T, 6) over one clip from a zero state, the module's own mean fed back.

    The output is r + w (mean - r), r the context read, as `policy_system.CchpPolicy` gives it.
    If `variances` is a list, each step's read variance factor v (`step_with_variance`) is appended.
    """
    import torch

    from rtcohand_drake.systems.policy import blended_output

    H = int(module.hidden_size)
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    x = torch.from_numpy(np.ascontiguousarray(features, np.float32))
    values_np = values.numpy()
    out = np.zeros((len(features), 6))
    with torch.no_grad():
        for t in range(len(features)):
            if variances is None:
                y, _, h, c, attention = module.step(x[t], y, h, c, keys, values, z)
            else:
                y, _, h, c, attention, v = module.step_with_variance(x[t], y, h, c, keys, values, z)
                variances.append(float(v[0]))
            out[t] = blended_output(y.numpy(), np.atleast_2d(attention.numpy()) @ values_np, correction_weight)
    return out


Groups = list[tuple[list[int], list[int]]]  # (clips to play, clips that are their context)


def fold_groups(n_clips: int, folds: int = 6) -> Groups:
    """Clip i in fold i % folds, played with the other folds as context."""
    if n_clips < 2:
        raise ValueError("need at least two labelled clips (one to play, one as context)")
    folds = max(2, min(folds, n_clips))
    return [(list(range(f, n_clips, folds)), [i for i in range(n_clips) if i % folds != f]) for f in range(folds)]


def split_groups(clips: Sequence[LabelledClip]) -> Groups:
    """The recorded-people protocol: the clips of split "test" played with those of split "train" as context."""
    test = [i for i, c in enumerate(clips) if c.split == "test"]
    train = [i for i, c in enumerate(clips) if c.split == "train"]
    if not test or not train:
        raise ValueError("the split protocol needs clips of split 'test' and of split 'train'")
    return [(test, train)]


def held_out_means(module, clips: Sequence[LabelledClip], folds: int = 6,
                   correction_weight: float = 1.0, lead: int = 0, groups: Groups | None = None,
                   progress=None) -> list:
    """The policy's output (T, 6) over every clip, each played with the other folds as context
    (or as `groups` say; a clip no group plays gets None).

    `lead` > 0 pairs each context frame with the label `lead` frames later (the context's last
    `lead` frames and first `lead` labels dropped): a read of what the person will want.
    `progress` (a tqdm bar, or anything with `update(n)`) advances by one per clip played."""
    import torch

    from rtcohand_drake.data.sampling import pack_context

    means: list = [None] * len(clips)
    for targets, context in groups or fold_groups(len(clips), folds):
        x_c, y_c, mask = pack_context([(clips[i].features[: len(clips[i].features) - lead], clips[i].labels[lead:])
                                       if lead else (clips[i].features, clips[i].labels) for i in context])
        with torch.no_grad():
            keys, values, z_mu, _ = module.encode_context(
                torch.from_numpy(x_c), torch.from_numpy(y_c), torch.from_numpy(mask))
        for i in targets:
            means[i] = play_clip(module, clips[i].features, keys, values, z_mu, correction_weight)
            if progress is not None:
                progress.update(1)
    return means


def held_out_reference_means(clips: Sequence[LabelledClip], folds: int = 6, window: int = 10,
                             lam: float = 100.0, groups: Groups | None = None, make=None,
                             all_features: bool = False, progress=None) -> list:
    """A fitted-to-the-person reference over every clip, solved on the other folds (or as `groups`
    say): by default the ridge regression (`rtcohand_drake.learning.ridge_reference`), or what
    `make()` gives (an unfitted reference with `fit(pieces)` and `predict(features)`). It reads the
    36 velocities, or with `all_features` every column the clips carry (the kernel reference).
    `progress` advances by one per clip read, as in `held_out_means`."""
    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.learning.ridge_reference import RidgeReference

    make = make or (lambda: RidgeReference(window, lam))
    cut = None if all_features else FEATURE_DIM
    means: list = [None] * len(clips)
    for targets, context in groups or fold_groups(len(clips), folds):
        reference = make().fit([(clips[i].features[:, :cut], clips[i].labels) for i in context])
        for i in targets:
            means[i] = reference.predict(clips[i].features[:, :cut])
            if progress is not None:
                progress.update(1)
    return means


def held_out_readings(module, clips: Sequence[LabelledClip], folds: int = 6, correction_weight: float = 1.0,
                      means: Sequence[np.ndarray] | None = None) -> list[ClipReading]:
    """The reading gain on each active dimension of every clip, played with the other folds as context
    (or read from `means`, the output of `held_out_means`, when given)."""
    if means is None:
        means = held_out_means(module, clips, folds, correction_weight)
    readings = []
    for clip, means in zip(clips, means):
        if means is None:  # not played (a context clip of the split protocol)
            continue
        for d in clip.active_dims:
            label = clip.labels[:, d]
            peak = np.max(np.abs(label))
            if peak <= 0:
                continue
            active = np.abs(label) > ACTIVE_SHARE * peak
            along = float(label[active].mean())
            readings.append(ClipReading(clip.name, int(d), int(np.sign(along)), float(means[active, d].mean() / along)))
    return readings


def motion_table(readings: Sequence[ClipReading]) -> list[tuple[str, int, float, str]]:
    """(motion, clips, median gain, verdict) for each motion with clips, in Tx+ Tx- ... Rz- order."""
    rows = []
    for d in range(6):
        for sign in (1, -1):
            gains = [r.gain for r in readings if r.dim == d and r.sign == sign]
            if gains:
                g = float(np.median(gains))
                rows.append((motion_name(d, sign), len(gains), g, verdict(g)))
    return rows


def one_motion(clip: LabelledClip) -> tuple[int, str, np.ndarray] | None:
    """(its dimension, its motion's name "Tx+", the steps where its label is active) of a clip with one
    active dimension and a label on it; None for any other clip."""
    if len(clip.active_dims) != 1:
        return None
    d = clip.active_dims[0]
    label = np.asarray(clip.labels, float)[:, d]
    peak = np.max(np.abs(label))
    if peak <= 0:
        return None
    active = np.abs(label) > ACTIVE_SHARE * peak
    return d, motion_name(d, 1 if label[active].mean() > 0 else -1), active


def confusions(clips: Sequence[LabelledClip], means: Sequence[np.ndarray | None],
               share: float = None) -> list[tuple[str, str, float]]:
    """(motion, the motion it is read as, how much) for each one-motion gesture whose played clips the
    read moves, in the median over them, along another motion by at least `share` (CONFUSED_SHARE) of the
    person's command on that axis (the largest label on it among the clips), over the steps where the
    gesture's own label is active. Two gestures that look alike to the read."""
    share = CONFUSED_SHARE if share is None else share
    sizes = np.max([np.abs(np.asarray(c.labels, float)).max(0) for c in clips], axis=0)
    crossed: dict[str, list[np.ndarray]] = {}
    for clip, out in zip(clips, means):
        motion = one_motion(clip) if out is not None else None
        if motion is None:
            continue
        d, name, active = motion
        along = np.where(sizes > 0, np.asarray(out, float)[active].mean(0) / np.where(sizes > 0, sizes, 1.0), 0.0)
        along[d] = 0.0
        crossed.setdefault(name, []).append(along)
    found = []
    for d in range(6):
        for name in (motion_name(d, 1), motion_name(d, -1)):
            if name not in crossed:
                continue
            rows = np.array(crossed[name])
            for e in range(6):
                for sign in (1, -1):
                    level = float(np.median(np.maximum(sign * rows[:, e], 0.0)))
                    if level >= share:
                        found.append((name, motion_name(e, sign), level))
    return found


def recordings_per_motion(clips: Sequence[LabelledClip]) -> dict[str, int]:
    """The one-motion clips of each motion (its name, "Tx+"; `one_motion`)."""
    counts: dict[str, int] = {}
    for motion in filter(None, map(one_motion, clips)):
        counts[motion[1]] = counts.get(motion[1], 0) + 1
    return counts


def recording_style(path: Path) -> str:
    """How the file's person gestured: the recorder's `protocol.style` ("hold" or "stroke"); "hold"
    for files the recorder did not write or written before the style was recorded."""
    from rtcohand_drake.data.dataset import DatasetError, recorder_protocol

    try:
        _, protocol = recorder_protocol(path)
    except (OSError, DatasetError):
        return "hold"
    return protocol.get("style", "hold")


def read_choice(module, clips: Sequence[LabelledClip]) -> str | None:
    """Which read a policy file that reads the hand's path and shape (`learning.path_shape_policy`) gives
    the person from all of their clips as context, and why, in one line; None for any other file."""
    if not hasattr(module, "blend_choice") or not hasattr(module, "fast_turn_share"):
        return None
    import torch

    from rtcohand_drake.data.sampling import pack_context

    x, y, m = (torch.from_numpy(a) for a in pack_context([(c.features, c.labels) for c in clips]))
    from rtcohand_drake.learning.path_shape_policy import encode_fitted

    used, _, _, cchp_error = (float(v) for v in module.blend_choice(encode_fitted(module, x, y, m)[0]))
    fast = float(module.fast_turn_share(x, m))
    why = (f"the CCHP alone reads these clips at {cchp_error:.2f} of zero twist's squared error (the kernel read "
           f"from {float(module.min_cchp_error):g}), and the palm turns faster than {float(module.fast_turn_rad_s):g} "
           f"rad/s in {fast:.0%} of their moving steps (from {float(module.min_fast_turns):.0%})")
    if used > 0:
        return f"read: the CCHP and the kernel read of the hand's path and shape, blended {used:.2f}: {why}"
    advice = ""
    if cchp_error >= float(module.min_cchp_error) and fast < float(module.min_fast_turns):
        advice = ("; a real hand tracked this smoothly: a file built with `python -m "
                  "rtcohand_drake.learning.path_shape_policy --policy models/cchp_default.pt --out FILE.pt "
                  "--min-fast-turns 0` gives it the kernel read (then --model FILE.pt)")
    return f"read: the CCHP alone: {why}{advice}"


def clips_from_file(paths, user: str | None, rate_hz: float,
                    path_shape: bool = False) -> tuple[list[LabelledClip], str]:
    """A user's labelled clips from a dataset file, or from several together (`--context-file A.h5
    B.h5`), and the user (`data.dataset.user_policy_clips`); `path_shape`: with the hand's path and
    shape (`to_policy_clip`)."""
    from rtcohand_drake.data.dataset import as_paths, user_policy_clips

    clips, user = user_policy_clips(paths, user, rate_hz, path_shape)
    mine = [LabelledClip(c.name, c.features, c.labels, tuple(int(d) for d in c.active_dims), c.split)
            for c in clips]
    if len(mine) < 2:
        where = " and ".join(map(str, as_paths(paths)))
        raise InputError(f"{where}: user {user!r} has {len(mine)} labelled clips; at least 2 are needed")
    return mine, user


def builtin_clips(user: str, rate_hz: float, population_seed: int | None = None,
                  path_shape: bool = False) -> list[LabelledClip]:
    """The labelled clips of a built-in simulated user (as `make_builtin_person` makes them), from the
    default population or the one `data.generate --seed population_seed` writes."""
    from rtcohand_drake.data.dataset import to_policy_clip
    from rtcohand_drake.data.population import GeneratorConfig, simulate_user
    from rtcohand_drake.data.population import DEFAULT_SEED
    from rtcohand_drake.systems.gestures.simulated_person import population_user_ids

    ids = population_user_ids()
    if user not in ids:
        raise InputError(f"--user: unknown user {user!r}; valid ids: {', '.join(ids)}")
    seed = DEFAULT_SEED if population_seed is None else population_seed
    _, raw, _ = simulate_user(GeneratorConfig(), list(ids).index(user), ids[user], seed)
    out = []
    for clip in raw:
        pc = to_policy_clip(clip, rate_hz, path_shape)
        out.append(LabelledClip(pc.name, pc.features, pc.labels, tuple(int(d) for d in clip.active_dims)))
    return out


def make_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m rtcohand_drake.context_reading", description=__doc__.splitlines()[0])
    p.add_argument("--context-file", type=Path, nargs="+", action="extend", default=None, metavar="PATH.h5",
                   help="dataset file(s) with the user's labelled clips; several files (say a first session "
                        "and one re-recording weak motions) are read together as one context")
    p.add_argument("--context-user", default=None,
                   help="which user of --context-file (needed when the files hold more than one)")
    p.add_argument("--user", default=None, help="a built-in simulated user instead (u00 .. u14)")
    p.add_argument("--population-seed", type=non_negative_int, default=None,
                   help="with --user: the generated population (data.generate --seed; default 0, the benchmark's)")
    p.add_argument("--scenario", default="inspection",
                   help="scenario whose policy settings (model, correction_weight) are checked")
    p.add_argument("--model", type=Path, default=None,
                   help="exported policy (default: the scenario's policy.model; for a real person's clips its "
                        "policy.real_hand_model where one is named)")
    p.add_argument("--correction-weight", type=float, default=None,
                   help="w of the policy's output r + w (mean - r) (default: the scenario's)")
    p.add_argument("--folds", type=int, default=6,
                   help="with --protocol folds: how many groups the clips are split into; each group is read "
                        "with the others as context (at least 2, default 6)")
    p.add_argument("--protocol", choices=("folds", "split"), default="folds",
                   help="folds: every clip read with the other folds as context; split: the clips of split "
                        "'test' read with those of split 'train' (recorded people, data.import_shrec17)")
    p.add_argument("--ridge", nargs=2, type=float, default=None, metavar=("WINDOW", "LAMBDA"),
                   help="the ridge reference's window (policy steps) and lambda (default 10 100)")
    p.add_argument("--knn", nargs=2, type=int, default=None, metavar=("WINDOW", "K"),
                   help="the nearest-neighbour reference's window (policy steps) and k (default 20 20)")
    p.add_argument("--rate-hz", type=positive_float, default=10.0,
                   help="the policy rate (Hz) the clips are resampled to before they are read (default 10, "
                        "the run's)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    return p


def check(argv: Sequence[str] | None = None) -> list[str]:
    """Runs the check (module docstring) and prints its table and advice; returns the motions read
    below half their size (verdicts `weak` and `poor`), in Tx+ ... Rz- order."""
    args = make_parser().parse_args(argv)
    if (args.context_file is None) == (args.user is None):
        raise InputError("command line: give either --context-file (with --context-user) or --user")
    if args.population_seed is not None and args.user is None:
        raise InputError("command line: --population-seed goes with --user")
    if args.folds < 2:
        raise InputError("command line: --folds must be >= 2")
    from rtcohand_drake.learning.evaluate import check_reference_args

    check_reference_args(args.ridge, args.knn)
    from rtcohand_drake.cell.robot_files import policy_file_path
    from rtcohand_drake.data.dataset import as_paths, is_generated
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.registry import policy_model_name

    scenario = load_scenario(args.scenario)
    weight = scenario.policy.correction_weight if args.correction_weight is None else args.correction_weight
    if not 0.0 <= weight <= 1.0:
        raise InputError(f"command line: --correction-weight must be in [0, 1], got {weight}")
    # Without --model: the scenario's policy.model (for a real person's clips, policy.real_hand_model
    # where one is named).
    real = args.context_file is not None and not all(is_generated(p) for p in as_paths(args.context_file))
    model = args.model or policy_file_path(policy_model_name(scenario.policy, real))
    module = load_policy(model)
    from rtcohand_drake.data.hand_features import FEATURE_DIM

    wide = int(module.feature_dim) > FEATURE_DIM  # a file that reads the hand's path and shape
    if args.user is not None:
        clips, who = builtin_clips(args.user, args.rate_hz, args.population_seed, wide), args.user
    else:
        clips, who = clips_from_file(args.context_file, args.context_user, args.rate_hz, wide)
    from rtcohand_drake.learning.evaluate import KNN_DEFAULT, RIDGE_DEFAULT
    from rtcohand_drake.learning.knn_reference import KnnReference

    if args.protocol == "split":
        try:
            groups = split_groups(clips)
        except ValueError as err:
            raise InputError(f"--protocol split: user {who}: {err}") from None
        how = f"the {len(groups[0][0])} clips of split 'test' read with the {len(groups[0][1])} of split 'train'"
    else:
        if len(clips) < 2:
            raise InputError(f"user {who}: need at least two labelled clips (one to play, one as context)")
        groups = fold_groups(len(clips), args.folds)
        how = f"each read with the other {len(groups) - 1} of {len(groups)} folds as context"
    ridge = tuple(args.ridge) if args.ridge else RIDGE_DEFAULT
    knn = tuple(args.knn) if args.knn else KNN_DEFAULT
    from tqdm import tqdm

    played_count = sum(len(targets) for targets, _ in groups)
    # Each played clip is read by the policy and by each reference (the kernel read with a wide file).
    bar = tqdm(total=played_count * (4 if wide else 3), desc=f"reading {who}'s clips", unit="read",
               file=sys.stderr, disable=args.no_progress, dynamic_ncols=True)
    with bar:
        means = held_out_means(module, clips, correction_weight=weight, groups=groups, progress=bar)
        references = {
            f"ridge (window {int(ridge[0])}, lambda {ridge[1]:g})": held_out_reference_means(
                clips, window=int(ridge[0]), lam=ridge[1], groups=groups, progress=bar),
            f"nearest neighbours (window {knn[0]}, k {knn[1]})": held_out_reference_means(
                clips, groups=groups, make=lambda: KnnReference(int(knn[0]), int(knn[1])), progress=bar),
        }
        if wide:  # the clips carry the hand's path and shape: the kernel read of it, fitted alike
            from rtcohand_drake.learning.kernel_reference import BANDWIDTH, LAMBDA, KernelReference

            references[f"kernel read of the path and shape (bandwidth {BANDWIDTH:g}, lambda {LAMBDA:g})"] = \
                held_out_reference_means(clips, groups=groups, make=KernelReference, all_features=True,
                                         progress=bar)
    readings = held_out_readings(module, clips, means=means)
    reference_gains = {label: {name: gain for name, _, gain, _ in
                               motion_table(held_out_readings(None, clips, means=m))}
                       for label, m in references.items()}
    played = [i for i, m in enumerate(means) if m is not None]
    zero = sum(float((clips[i].labels ** 2).sum()) for i in played)

    def share(outputs) -> float:
        return sum(float(((outputs[i] - clips[i].labels) ** 2).sum()) for i in played) / max(zero, 1e-12)

    rows = motion_table(readings)
    print(f"user {who}: {len(clips)} labelled clips, {how}; policy {model.name}, correction weight {weight:g}")
    labels = list(references)
    print("| motion | clips | reading gain (median) | verdict | " + " | ".join(f"{r} gain" for r in labels) + " |")
    print("|---|---|---|---|" + "---|" * len(labels))
    for name, n, gain, word in rows:
        print(f"| {name} | {n} | {gain:+.2f} | {word} | "
              + " | ".join(f"{reference_gains[r].get(name, float('nan')):+.2f}" for r in labels) + " |")
    print(f"median reading gain over all {len(readings)} clip motions: "
          f"{np.median([r.gain for r in readings]):+.2f}")
    print(f"held-out squared error over the played clips: {share(means):.3f} of commanding zero twist "
          f"(fitted to the person's context: " + ", ".join(f"{r} {share(m):.3f}" for r, m in references.items())
          + ")")
    choice = read_choice(module, clips) if wide else None
    if choice:
        print(choice)
    weak = [name for name, _, gain, _ in rows if gain < READS]
    print("read below half their size: " + (", ".join(weak) if weak else "none"))
    crossed = confusions(clips, means)
    if crossed:
        print(CONFUSED_ADVICE.format(pairs=", ".join(f"{a} as {b} ({v:.2f} of its size)" for a, b, v in crossed)))
    counts = recordings_per_motion(clips)
    few = [(name, counts[name]) for d in range(6) for name in [motion_name(d, 1), motion_name(d, -1)]
           if 0 < counts.get(name, 0) < RECORDINGS]
    if few:
        print(FEW_ADVICE.format(n=RECORDINGS, motions=", ".join(f"{m} ({k})" for m, k in few),
                                only=",".join(m for m, _ in few)))
    if real and scenario.policy.rest_release:  # a real person's clips: does the command let go at rest?
        from rtcohand_drake.data.dataset import label_lag_s
        from rtcohand_drake.learning.rest_release import fit_rest_release, release_advice

        lag = label_lag_s(args.context_file) if args.context_file else 0.0
        release = fit_rest_release([(c.features, c.labels) for c in clips], int(round(lag * args.rate_hz)))
        print(release_advice(release) or (f"the rest release is on for these clips: the command lets go once the "
                                           f"hand has been still for {release.still_to / args.rate_hz:.1f} s"))
    poor = [name for name, _, gain, _ in rows if gain < WEAK]
    shape = reference_gains[labels[1]]
    by_shape = [name for name in poor if shape.get(name, float("nan")) >= READS]
    unread = [name for name in poor if name not in by_shape]
    # Strokes on purpose when every file given was recorded so (`record --style stroke`).
    style = ("stroke" if args.context_file and all(recording_style(f) == "stroke" for f in args.context_file)
             else "hold")
    if by_shape and style == "stroke":
        print(STROKE_STYLE_ADVICE.format(motions=", ".join(by_shape), only=",".join(by_shape)))
    elif by_shape:
        print(STROKE_ADVICE.format(motions=", ".join(by_shape)))
    if unread:
        print(POOR_ADVICE.format(motions=", ".join(unread)))
    return weak


def main(argv: Sequence[str] | None = None) -> int:
    check(argv)
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.context_reading"))


if __name__ == "__main__":
    entry_point()
