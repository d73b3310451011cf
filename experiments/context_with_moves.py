"""Does the read let go of the hand's moves between gestures once the context shows such moves with
no command?

    python experiments/context_with_moves.py --data PEOPLE.h5 --out MOVES.h5 [--people s02 s04 ...]
    python -m rtcohand_drake.study --recorded-people MOVES.h5 --out DIR --people ... --conditions responsive

Writes a copy of the recorded people's file in which each person's context clips (`split = train`)
start with the hand's move from where their previous context clip left it into the clip's first
shape, with no command (the recorded source's join: `recorded_person.blend_hands`, over at least
`RecordedHandConfig.join_s`, longer where a point has further to go than its speed or a bone to
turn than its rate allow). Their held-out clips (`split = test`) are copied as they are, so the
recorded hand plays the same gestures. A study of the copy against one of the original file tells
how much of the rest drift comes from a context that never shows such a move.

This is a diagnosis, not a product setting: the moves added are the recorded source's own joins,
so the copy shows the read exactly the moves it will meet. A person recorded with the camera shows
their own moves, if any, in the unlabelled time of their clips.
"""

from __future__ import annotations

import argparse
import dataclasses as dc

import numpy as np


def with_lead_in(clip, start: np.ndarray, config) -> object:
    """`clip` with the move from skeleton `start` into its first frame put before it, no command."""
    from rtcohand_drake.systems.gestures.recorded_person import PALM, blend_hands, join_time
    from rtcohand_drake.systems.gestures.simulated_person import smoothstep

    first = np.asarray(clip.keypoints[0], float)
    if not (np.isfinite(first).all() and np.isfinite(start).all()):
        return clip
    # As the recorded source joins: the clip moved so that its palm centre starts where the hand is.
    offset = start[list(PALM)].mean(axis=0) - first[list(PALM)].mean(axis=0)
    seconds = max(config.join_s, join_time(start, first + offset, config))
    n = max(1, int(round(seconds * clip.fps)))
    move = np.stack([blend_hands(start, first + offset, smoothstep(k / n)) for k in range(n)]) - offset
    keypoints = np.concatenate([move, clip.keypoints]).astype(np.float32)
    velocity = np.concatenate([np.zeros((n, 6)), clip.object_velocity]).astype(np.float32)
    return dc.replace(clip, keypoints=keypoints, object_velocity=velocity, object_pose=None, timestamps=None)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a recorded people's dataset file (the importer's)")
    p.add_argument("--out", required=True, help="the copy to write")
    p.add_argument("--people", nargs="+", default=None, help="these people only (default: all)")
    args = p.parse_args(argv)

    from rtcohand_drake.data.dataset import read_dataset, write_dataset
    from rtcohand_drake.systems.gestures.recorded_person import RecordedHandConfig

    config = RecordedHandConfig()
    clips = [c for c in read_dataset(args.data) if args.people is None or c.user in args.people]
    out, last = [], {}
    for clip in clips:  # user, then clip name order
        if clip.split == "train" and clip.object_velocity is not None and clip.user in last:
            out.append(with_lead_in(clip, last[clip.user], config))
        else:
            out.append(clip)
        if clip.split == "train":
            last[clip.user] = np.asarray(clip.keypoints[-1], float)
    # No `generator` attribute: that would mark the copy as generated people, read with `policy.model`
    # in place of the file for real hands (`data.dataset.is_generated`).
    write_dataset(args.out, out, root_attrs={"derived_by": "experiments/context_with_moves.py"})
    added = sum(a.num_frames - b.num_frames for a, b in zip(out, clips))
    print(f"wrote {args.out}: {len(out)} clips of {len({c.user for c in out})} people, {added} frames of moves "
          f"between gestures added to their context clips", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
