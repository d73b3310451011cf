"""Where does a recorded person's unfinished run get stuck? The motion they keep gesturing at the end, and how
much of it the read gives.

    python experiments/stuck_motion.py --logs DIR/logs/*_responsive_*.h5 [--last 300] [--data PEOPLE.h5]

For each run log of `study --recorded-people` that did not complete: over its last `--last` seconds, the
policy steps in which the person gestures (the label of the frame played over a fifth of a full command on
some axis: 0.12 m/s, 0.6 rad/s), the motion of each such step (the label's largest axis as a share of a full
command, with its sign), the three motions gestured most, and per axis the policy's gain over those steps:
the least-squares factor of its output (`policy/mean`) on the label, sum(mean y) / sum(y^2), over the steps
where that axis is gestured (1: the label's size; at least 20 steps). `study --recorded-people` reports
the command gestured most in a run's last 60 s and the gain along it (`gesture_following.stuck_motion`);
this looks further back and at every axis. With `--data` (the study's file of
recorded people), the person's held-out recordings of the motion gestured most are also read alone, open
loop, with their `split = train` clips as context, as `benchmarks/back_to_back_read.py` reads a clip by
itself (the run's policy file, the rest release): the gain along the motion's axis over the steps where
it is gestured. The findings: docs/real_people.md, "Given more time".
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

from rtcohand_drake.analysis.gesture_following import AXES, FULL_COMMAND

SHARE = 0.2  # a gesture under way: a fifth of a full command


def stuck(path: pathlib.Path, last_s: float) -> dict | None:
    """The figures of one run log (module docstring); None for a completed run."""
    from rtcohand_drake.run_log import read_run_log

    log = read_run_log(path)
    if log.completed:
        return None
    t, label, mean = log.gesture_time, log.gesture_intended, log.policy_mean
    keep = t > t[-1] - last_s if len(t) else np.zeros(0, bool)
    size = np.abs(label[keep]) / FULL_COMMAND
    gesturing = (size > SHARE).any(1)
    counts: dict[str, int] = {}
    for i in np.flatnonzero(gesturing):
        d = int(np.argmax(size[i]))
        name = AXES[d] + ("+" if label[keep][i, d] > 0 else "-")
        counts[name] = counts.get(name, 0) + 1
    gains = {}
    for d, axis in enumerate(AXES):
        on = size[:, d] > SHARE
        if on.sum() >= 20:
            gains[axis] = float((mean[keep][on, d] * label[keep][on, d]).sum() / (label[keep][on, d] ** 2).sum())
    return {"faces": int(log.faces_inspected), "gesturing_steps": int(gesturing.sum()), "model": log.model,
            "motions": sorted(counts.items(), key=lambda kv: -kv[1])[:3], "gains": gains}


def read_alone(data: pathlib.Path, person: str, motion: str, model: str) -> list[float]:
    """The gain along `motion`'s axis of each of the person's held-out recordings of it, read alone."""
    import sys

    import torch

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from back_to_back_read import person_streams

    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.data.dataset import read_dataset
    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.learning.rest_release import fit_rest_release, guard_stream

    module = load_policy(model)
    streams = person_streams(read_dataset(data), person, 10.0, int(module.feature_dim) > 36)
    if streams is None:
        return []
    context, single, _ = streams
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    with torch.no_grad():
        keys, values, z, _ = module.encode_context(x_c, y_c, mask)
    gate = fit_rest_release(context)
    d, sign = AXES.index(motion[:2]), (1.0 if motion[2] == "+" else -1.0)
    gains = []
    for features, labels, keypoints in single:
        size = np.abs(labels) / FULL_COMMAND
        if int(np.argmax(size.max(0))) != d or np.sign(labels[:, d].sum()) != sign:
            continue
        guarded = guard_stream(gate, np.nan_to_num(features), keypoints, 10.0)
        out = play_clip(module, guarded, keys, values, z) * gate.gates(guarded)[:, None]
        on = size[:, d] > SHARE
        gains.append(float((out[on, d] * labels[on, d]).sum() / (labels[on, d] ** 2).sum()))
    return gains


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--logs", nargs="+", required=True, type=pathlib.Path, help="study run logs (.h5)")
    p.add_argument("--last", type=float, default=300.0, help="seconds at the end of each run to read")
    p.add_argument("--data", type=pathlib.Path, default=None,
                   help="the study's file of recorded people: also read the stuck motion's held-out recordings alone")
    args = p.parse_args(argv)
    for path in sorted(args.logs):
        r = stuck(path, args.last)
        if r is None:
            continue
        motions = ", ".join(f"{m} {c}" for m, c in r["motions"]) or "none"
        gains = ", ".join(f"{a} {g:+.2f}" for a, g in r["gains"].items()) or "-"
        alone = ""
        if args.data is not None and r["motions"]:
            person = path.name.split("_")[0]
            read = read_alone(args.data, person, r["motions"][0][0], r["model"])
            alone = f"; its held-out recording read alone: gain {', '.join(f'{g:+.2f}' for g in read) or '-'}"
        print(f"{path.name}: {r['faces']}/6 faces; last {args.last:.0f} s: {r['gesturing_steps']} gesturing steps "
              f"({motions}); the read's gain per axis: {gains}{alone}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
