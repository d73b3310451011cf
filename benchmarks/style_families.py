"""People of style families the generator does not make: a population whose commands mean other things.

    python benchmarks/style_families.py --data population.h5 --family swapped --out FAMILY.h5

Every person of the population keeps their hands' motion; what each of their gestures commands is
remapped, the same way for every person of the family, so that no training population has people
like them (the generator's people flip X and Y when mirrored and flip single axes; they never
exchange axes, nor turn for a move):

- `swapped`: across and up exchanged, for moves and turns (Tx <-> Tz, Rx <-> Rz);
- `roll_for_yaw`: a turn about the vertical axis commands a roll about the forward one, and back
  (Ry <-> Rz);
- `turn_for_move`: every move commands the turn about the same axis and every turn the move
  (Tx <-> Rx, ..., at the label magnitudes' ratio, 0.12 m/s for 0.6 rad/s);
- `inverted`: every command reversed.

The labels' magnitudes, timing and noise are the person's own. The file is the population's with
the labels (and the object's pose, dropped) replaced; the evaluation settings read it as any
population (`benchmarks/stepped_share.py`, `python -m rtcohand_drake.evaluate`).
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RATIO = 0.12 / 0.6  # m/s per rad/s: the handler's nominal speed over its turn rate
# family -> for each label axis d (Tx .. Rz): (the axis it becomes, the factor)
FAMILIES = {
    "swapped": [(2, 1.0), (1, 1.0), (0, 1.0), (5, 1.0), (4, 1.0), (3, 1.0)],
    "roll_for_yaw": [(0, 1.0), (1, 1.0), (2, 1.0), (3, 1.0), (5, 1.0), (4, 1.0)],
    "turn_for_move": [(3, 1.0 / RATIO), (4, 1.0 / RATIO), (5, 1.0 / RATIO), (0, RATIO), (1, RATIO), (2, RATIO)],
    "inverted": [(d, -1.0) for d in range(6)],
}


def remap(labels: np.ndarray, family: str) -> np.ndarray:
    out = np.zeros_like(labels)
    for d, (to, factor) in enumerate(FAMILIES[family]):
        out[:, to] = labels[:, d] * factor
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a generated population file")
    p.add_argument("--family", required=True, choices=sorted(FAMILIES))
    p.add_argument("--out", required=True, help="the file to write")
    args = p.parse_args(argv)
    from rtcohand_drake.data.dataset import read_dataset, write_dataset

    clips = []
    for c in read_dataset(args.data):
        if c.object_velocity is None:
            clips.append(c)
            continue
        labels = remap(np.asarray(c.object_velocity, np.float64), args.family).astype(c.object_velocity.dtype)
        dims = np.array(sorted({FAMILIES[args.family][d][0] for d in c.active_dims}), dtype=np.int64)
        clips.append(dataclasses.replace(c, object_velocity=labels, object_pose=None, active_dims=dims))
    write_dataset(args.out, clips, generator=f"style family {args.family} of {pathlib.Path(args.data).name}")
    print(f"wrote {args.out}: {len(clips)} clips, family {args.family}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
