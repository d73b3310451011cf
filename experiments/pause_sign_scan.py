"""How often do recorded gestures make the pause hand sign, for each setting of the sign's
`axis_from_up_min_deg` (`systems.hand_sign`)?

    python experiments/pause_sign_scan.py --data PEOPLE.h5 --people s02 s04 ... [--axis-min 0 40 50 60]

Each clip of the people is played as the recorded source plays it, at the policy rate (10 Hz): its
first labelled shape held 1 s, the labelled gesture, its last shape held 2 s (the recorded person
rests in the shape the gesture left). Every step goes through the sign's own `sign_step`, armed
(the hand seen open before), with the scenario's other settings. Prints, per setting, the clips
after which the sign toggled, by gesture.
"""

from __future__ import annotations

import argparse
import collections

import numpy as np

RATE_HZ = 10.0
BEFORE_S, AFTER_S = 1.0, 2.0


def played(keypoints: np.ndarray, labels: np.ndarray, fps: float) -> np.ndarray:
    """(T, 21, 3) the labelled part of a clip at the policy rate, its first shape held before and its
    last after (module docstring)."""
    on = np.nonzero(np.abs(labels).max(1) > 0)[0]
    gesture = keypoints[on[0]:on[-1] + 1][::max(1, int(round(fps / RATE_HZ)))]
    return np.concatenate([np.repeat(gesture[:1], int(BEFORE_S * RATE_HZ), 0), gesture,
                           np.repeat(gesture[-1:], int(AFTER_S * RATE_HZ), 0)])


def toggles(frames: np.ndarray, config) -> int:
    from rtcohand_drake.systems.hand_sign import initial_state, sign_step

    state = initial_state()
    state[2] = 1.0  # armed: the hand was seen open before the clip
    for i, kp in enumerate(frames):
        state = sign_step(state, kp, i / RATE_HZ, config)
    return int(state[4])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a gesture dataset file (the importer's)")
    p.add_argument("--people", nargs="+", required=True, help="the users whose clips to play")
    p.add_argument("--axis-min", nargs="+", type=float, default=[0.0, 40.0, 50.0, 60.0],
                   help="settings of hand_sign.axis_from_up_min_deg to try")
    args = p.parse_args(argv)

    from rtcohand_drake.data.dataset import read_dataset
    from rtcohand_drake.systems.hand_sign_config import HandSign

    clips = [c for c in read_dataset(args.data) if c.user in set(args.people) and c.object_velocity is not None
             and np.abs(c.object_velocity).max() > 0]
    for axis in args.axis_min:
        config = HandSign(axis_from_up_min_deg=axis)
        by_gesture = collections.Counter()
        for clip in clips:
            if toggles(played(np.asarray(clip.keypoints, float), np.asarray(clip.object_velocity), clip.fps), config):
                by_gesture[(clip.description or clip.clip_id).split(",")[0]] += 1
        detail = ", ".join(f"{g} {n}" for g, n in sorted(by_gesture.items()))
        print(f"axis at least {axis:g} deg from up: the sign toggled after {sum(by_gesture.values())} of "
              f"{len(clips)} clips" + (f" ({detail})" if detail else ""), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
