"""How much does the closed loop of recorded people depend on which repetition of each gesture is held out?

    python experiments/held_out_repetition.py --data MAP.h5 --out COPY.h5 --people s02 s04 ...

The importer (`data.import_shrec17`) holds out each variant's last repetition (`split = test`), which the
recorded person then plays every time the task asks for that motion. This writes a copy of the file in
which, for each person named, each variant with a held-out repetition holds out its first repetition
instead (by clip name: the lowest `eNN`) and gives the last one to the context. Run the study on both
files (`python -m rtcohand_drake.study --recorded-people COPY.h5 --people ... --conditions responsive`)
and compare. The findings: docs/real_people.md, "Given more time". Development people only.
"""

from __future__ import annotations

import argparse
import dataclasses


def main(argv=None) -> int:
    from rtcohand_drake.data.dataset import read_dataset, write_dataset

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a file of recorded people written by the importer")
    p.add_argument("--out", required=True)
    p.add_argument("--people", nargs="+", required=True)
    args = p.parse_args(argv)
    clips = read_dataset(args.data)
    variants: dict[tuple[str, str], list[int]] = {}
    for i, c in enumerate(clips):
        if c.user in args.people:
            variants.setdefault((c.user, c.clip_id.rsplit("e", 1)[0]), []).append(i)
    out, swapped = list(clips), 0
    for rows in variants.values():
        test = [i for i in rows if clips[i].split == "test"]
        train = sorted((i for i in rows if clips[i].split == "train"), key=lambda i: clips[i].clip_id)
        if test and train:
            out[test[0]] = dataclasses.replace(clips[test[0]], split="train")
            out[train[0]] = dataclasses.replace(clips[train[0]], split="test")
            swapped += 1
    write_dataset(args.out, out)
    print(f"wrote {args.out}: the first repetition held out in place of the last for {swapped} variants")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
