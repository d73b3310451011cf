"""Where does the read point against a recorded gesture, and would refusing reversals before a rest help?

    python experiments/reversal_clamp.py --data MAP.h5 --people s02 s04 ... [--model models/cchp_path_shape.pt]
        [--allow-after 3 5 8 1000]

Each person's held-out clips back to back, read as `benchmarks/back_to_back_read.py` reads them
(the box's jump guard and rest release, no command hold), with their training clips as context.

1. **Where**: the steps with a gesture under way in which the output along its command is below
   minus a fifth of it (`analysis.replay_read.read_figures`' "against"), by how many steps the
   gesture's label has been under way, and by the command and the axis the output is largest on.
2. **A reversal clamp**, offline: an axis whose output has reached a fifth of a full command keeps
   that sign until the hand rests (the rest release's still count reaches 2); an output against it
   (above 5 % of a command) is zero, unless it has pointed against it for `--allow-after` steps in a
   row (then the sign may change). Squared error as a share of zero twist, steps against the
   gesture, and rest steps over a fifth of a command, pooled over the people.
"""

from __future__ import annotations

import argparse
import collections
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

LOW = 0.05  # below this share of a command an output is too small to count as a reversal
STILL = 2  # the still count at which the hand has rested (the rest release's gate is then falling)


def clamp_reversals(out: np.ndarray, still: np.ndarray, allow_after: int, full: np.ndarray,
                    high: float) -> np.ndarray:
    """The outputs (T, 6) with each reversal before a rest zeroed (module docstring)."""
    out = out.copy()
    sign, against = np.zeros(6), np.zeros(6)
    for t in range(len(out)):
        if still[t] >= STILL:
            sign[:], against[:] = 0.0, 0.0
        for a in range(6):
            v = out[t, a] / full[a]
            if sign[a] != 0 and np.sign(v) == -sign[a] and abs(v) > LOW:
                against[a] += 1
                if against[a] < allow_after:
                    out[t, a] = 0.0
                    continue
                sign[a], against[a] = (np.sign(v) if abs(v) >= high else 0.0), 0.0
            else:
                against[a] = 0.0
            if abs(v) >= high:
                sign[a] = np.sign(v)
    return out


def main(argv=None) -> int:
    import torch

    from back_to_back_read import person_streams
    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.analysis.replay_read import FULL, SHARE, read_figures
    from rtcohand_drake.data.dataset import read_dataset
    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.learning.rest_release import fit_rest_release, guard_stream, motions

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True)
    p.add_argument("--people", nargs="+", required=True)
    p.add_argument("--model", default=str(ROOT / "models" / "cchp_path_shape.pt"))
    p.add_argument("--allow-after", type=int, nargs="+", default=[3, 5, 8, 1000])
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    clips = read_dataset(args.data)
    module = load_policy(args.model)
    wide = int(module.feature_dim) > 36
    names = "xyzXYZ"  # x y z: the moves, X Y Z: the turns
    into, by_command, under_way, confused = collections.Counter(), collections.Counter(), collections.Counter(), \
        collections.Counter()
    totals = {k: np.zeros(6) for k in [0] + args.allow_after}
    for user in args.people:
        streams = person_streams(clips, user, 10.0, wide)
        if streams is None:
            continue
        context, _, (features, labels, keypoints) = streams
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
        with torch.no_grad():
            keys, values, z, _ = module.encode_context(x_c, y_c, mask)
        release = fit_rest_release(context)
        guarded = guard_stream(release, np.nan_to_num(features), keypoints if wide else None)
        out = play_clip(module, guarded, keys, values, z) * release.gates(guarded)[:, None]
        still, n = np.zeros(len(guarded)), 0.0
        for t, m in enumerate(motions(guarded)):
            n = n + 1.0 if m < release.theta else 0.0
            still[t] = n
        scaled = labels / FULL
        axis = np.abs(scaled).argmax(1)
        rows = np.arange(len(labels))
        going = np.abs(scaled[rows, axis]) >= SHARE
        along = np.sign(scaled[rows, axis]) * out[rows, axis] / FULL[axis]
        run = 0
        for t in range(len(labels)):
            run = (run + 1 if t and going[t - 1] and axis[t] == axis[t - 1] else 1) if going[t] else 0
            command = f"{'+' if scaled[t, axis[t]] > 0 else '-'}{names[axis[t]]}"
            if going[t]:
                under_way[command] += 1
            if going[t] and along[t] < -SHARE:
                into[min(run, 12)] += 1
                by_command[command] += 1
                largest = int(np.abs(out[t] / FULL).argmax())
                confused[(command, f"{'+' if out[t, largest] > 0 else '-'}{names[largest]}")] += 1
        for k in totals:
            o = out if k == 0 else clamp_reversals(out, still, k, FULL, SHARE)
            f = read_figures(o, labels, 10.0)
            totals[k] += [f.error, f.zero, f.against, f.gesture_steps, f.rest_moving, f.rest_steps]
    print(f"{pathlib.Path(args.data).name}, {len(args.people)} people")
    print("steps against the gesture, by steps its label has been under way (12: 12 or more):",
          dict(sorted(into.items())))
    print("by command (against / under way):", {c: f"{by_command[c]}/{under_way[c]}" for c in sorted(under_way)})
    print("the command and the output's largest axis when against:", confused.most_common(8))
    for k, (err, zero, against, steps, rest_moving, rest) in totals.items():
        label = "no clamp" if k == 0 else f"clamp, reversal allowed after {k} steps"
        print(f"{label}: share of zero twist {err / zero:.4f}, against the gesture {100 * against / steps:.1f} %, "
              f"rest steps over a fifth {100 * rest_moving / max(rest, 1):.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
