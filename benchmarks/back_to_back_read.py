"""How policy files read a person's held-out gestures made back to back, and whether they let go at rest.

    python benchmarks/back_to_back_read.py --data PEOPLE.h5 [--people s02 s04 ...] [--models A.pt B.pt]
        [--out FILE.json]

For each person of a gesture dataset file (the recorded people of `data.import_shrec17`, or any
file with `train` and `test` splits): the person's `test` clips are played one after another as
one stream, in clip order, with their `train` clips as context, as `run --gesture-source replay`
plays them: each clip's own 36 hand-part velocities, and the skeletons joined where the hand is
(`hand_features.join_recordings`) for the hand's path and shape. The policy's memory (recurrent
state, path lags, time warp) carries from one gesture to the next. Each file is stepped as the
policy box steps it (`analysis.context_reading.play_clip`: zero state at the start, its own mean
fed back, z the mean of q(z|C)); what is scored is the policy's output, before the filter.

Figures, for each file (medians over people, and the share over all steps pooled):
- `back_to_back`: squared error of the stream as a share of commanding zero twist;
- `clip_by_clip`: the same clips read one at a time from a zero state (the `Person` setting of
  `evaluate`);
- `rest_share`: of the rest steps (from 0.5 s after a gesture's label ends until the next label
  starts), the share in which the output exceeds a fifth of a full command on any axis
  (0.12 m/s or 0.6 rad/s: the importer's label magnitudes);
- `wrong_way_share`: of the steps with a gesture under way (a label at least a fifth of a full
  command), the share in which the output along the gesture's command is below minus a fifth of it.

The figures are `analysis.replay_read`'s, which scores a replay run's log the same way
(`run --gesture-source replay --clip PERSON --split test` prints them at the end of the run).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

def person_streams(clips, user: str, rate_hz: float, path_shape: bool):
    """(context pieces, [(features, labels, keypoints) of each test clip], (features, labels, keypoints)
    of them back to back); features are the 36 (path and shape are added by `read_person`, as the box
    adds them), keypoints (T, 21, 3) at the policy times, NaN when lost."""
    from rtcohand_drake.data.dataset import to_policy_clip
    from rtcohand_drake.data.hand_features import (frame_times, hand_features, interpolate_keypoints,
                                                   join_recordings, policy_times, resample)

    own = [c for c in clips if c.user == user and c.object_velocity is not None]
    context = [to_policy_clip(c, rate_hz, path_shape) for c in own if c.split == "train"]
    tests = sorted((c for c in own if c.split == "test"), key=lambda c: c.clip_id)
    if not context or not tests or len({c.fps for c in tests}) != 1:
        return None

    def policy_rate(keypoints, labels, fps):
        features, _ = hand_features(keypoints, fps, rate_hz)
        times = frame_times(len(keypoints), fps)
        kq, known = interpolate_keypoints(keypoints, times, policy_times(times, rate_hz), 1.5 / fps)
        kq[~known] = np.nan
        y, _ = resample(np.asarray(labels, np.float64), times, rate_hz)
        n = min(len(features), len(y))
        return features[:n], y[:n], kq[:n]

    single = [policy_rate(c.keypoints, c.object_velocity, c.fps) for c in tests]
    # As `run --gesture-source replay` plays them: each clip's own features one after another, the
    # skeletons joined where the hand is (hand_features.join_recordings).
    joined = join_recordings([kq for _, _, kq in single])
    stream = tuple(np.concatenate(a) for a in ([f for f, _, _ in single], [y for _, y, _ in single], joined))
    return [(p.features, p.labels) for p in context], single, stream


def read_person(module, context, single, stream, rate_hz: float, release: bool, hold: bool = True,
                label_lag_s: float = 0.0) -> dict:
    """The figures of one person (module docstring); with `release`, the output gated by the person's
    rest release (`learning.rest_release`) as the policy box gates it; with `hold`, then held as the
    box holds it where the file asks for it (`learning.command_hold`)."""
    import torch

    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.analysis.replay_read import read_figures
    from rtcohand_drake.learning.command_hold import fit_hold, hold_settings
    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.rest_release import fit_rest_release, guard_stream

    x_c, y_c, mask = pack_context(context)
    with torch.no_grad():
        keys, values, z_mu, _ = module.encode_context(torch.from_numpy(x_c), torch.from_numpy(y_c),
                                                      torch.from_numpy(mask))
    gate = fit_rest_release(context, int(round(label_lag_s * rate_hz)))  # as the policy box fits it
    gate.on = gate.on and release
    held = fit_hold(hold_settings(module), context) if hold else None
    wide = int(module.feature_dim) > 36

    def read(f, kq):
        f = guard_stream(gate, np.nan_to_num(f), kq if wide else None, rate_hz)
        out = play_clip(module, f, keys, values, z_mu) * gate.gates(f)[:, None]
        return held.apply(out) if held is not None else out

    err_single = sum(float(((read(f, kq) - y) ** 2).sum()) for f, y, kq in single)
    zero_single = sum(float((np.asarray(y, np.float64) ** 2).sum()) for _, y, _ in single)
    f, y, kq = stream
    out = read(f, kq)
    result = {"clip_by_clip": err_single / zero_single, "back_to_back": float(((out - y) ** 2).sum() / (y ** 2).sum()),
              "clip_by_clip_error": err_single, "clip_by_clip_zero": zero_single,
              "back_to_back_error": float(((out - y) ** 2).sum()), "back_to_back_zero": float((y ** 2).sum()),
              "release_on": bool(gate.on), "release_harm": float(gate.harm), "hold": held is not None}
    figures = read_figures(out, y, rate_hz)
    result.update({k: getattr(figures, k) for k in ("rest_steps", "rest_moving", "gesture_steps", "against")})
    result["rest_share"] = result["rest_moving"] / max(result["rest_steps"], 1)
    result["wrong_way_share"] = result["against"] / max(result["gesture_steps"], 1)
    return result


def summary(people: dict) -> dict:
    rows = list(people.values())
    pooled = lambda a, b: sum(r[a] for r in rows) / max(sum(r[b] for r in rows), 1)
    return {"people": len(rows),
            **{f"median_{k}": float(np.median([r[k] for r in rows]))
               for k in ("clip_by_clip", "back_to_back", "rest_share", "wrong_way_share")},
            "pooled_clip_by_clip": pooled("clip_by_clip_error", "clip_by_clip_zero"),
            "pooled_back_to_back": pooled("back_to_back_error", "back_to_back_zero"),
            "pooled_rest_share": pooled("rest_moving", "rest_steps"),
            "release_on": sum(bool(r["release_on"]) for r in rows),
            "pooled_wrong_way_share": pooled("against", "gesture_steps")}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a gesture dataset file with train and test splits")
    p.add_argument("--people", nargs="+", default=None, help="users to read (default: every user in the file)")
    p.add_argument("--models", nargs="+", default=["models/cchp_default.pt"], help="policy files to compare")
    p.add_argument("--rate-hz", type=float, default=10.0, help="the policy rate")
    p.add_argument("--no-release", action="store_true", help="read without the rest release (the box's "
                   "policy.rest_release: false)")
    p.add_argument("--no-hold", action="store_true", help="read without the command hold (the box's "
                   "policy.command_hold: false)")
    p.add_argument("--out", default=None, help="write the figures to this JSON file")
    args = p.parse_args(argv)

    import torch
    from tqdm import tqdm

    from rtcohand_drake.data.dataset import label_lag_s, read_dataset
    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.learning.policy_file import load_policy

    torch.set_num_threads(1)
    clips = read_dataset(args.data)
    users = args.people or sorted({c.user for c in clips})
    result = {"data": pathlib.Path(args.data).name, "people": users, "rest_release": not args.no_release,
              "command_hold": not args.no_hold, "models": {}}
    for name in args.models:
        module = load_policy(name)
        wide = int(module.feature_dim) > FEATURE_DIM
        people = {}
        for user in tqdm(users, desc=pathlib.Path(name).name, unit="person", file=sys.stderr):
            streams = person_streams(clips, user, args.rate_hz, wide)
            if streams is not None:
                people[user] = read_person(module, *streams, args.rate_hz, not args.no_release, not args.no_hold,
                                           label_lag_s(args.data))
        s = summary(people)
        result["models"][pathlib.Path(name).name] = {"summary": s, "people": people}
        print(f"{pathlib.Path(name).name}: {s['people']} people; share of zero twist (all steps pooled / median "
              f"of people) {s['pooled_clip_by_clip']:.3f} / {s['median_clip_by_clip']:.3f} clip by clip, "
              f"{s['pooled_back_to_back']:.3f} / {s['median_back_to_back']:.3f} back to back; "
              f"rest steps over a fifth of a command {100 * s['pooled_rest_share']:.1f} % "
              f"(median {100 * s['median_rest_share']:.1f} %); against the gesture "
              f"{100 * s['pooled_wrong_way_share']:.1f} %; rest release on for {s['release_on']}", flush=True)
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
