"""Where a recorded person's closed loop loses its command: the supervisor's confidence scale during
gestures, and which way the policy points when it commands at rest.

    python experiments/recorded_run_anatomy.py --logs DIR/logs/*_responsive_*.h5

DIR is the output of `python -m rtcohand_drake.study --recorded-people PEOPLE.h5 --out DIR`. Per run:

- speed scale: the supervisor's confidence scale (`command/speed_scale`) over the command samples
  with a gesture under way (the played frame's label non-zero), its 10th / 50th / 90th percentile;
- command / policy: the median, over those samples with a policy output over a tenth of a full
  command, of the command's size over the policy output's (each axis as a share of a full command:
  0.12 m/s, 0.6 rad/s);
- rest output: the policy steps at rest (from 0.5 s after a gesture's label until the next, the study's
  `drift_share` window) with an output over a fifth of a full command on any axis, and how they point:
  toward the next gesture's command (cosine over 0.5), along the previous one's, or neither; and the
  median time from such a step to the next gesture.
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

FULL = np.array([0.12, 0.12, 0.12, 0.6, 0.6, 0.6])
REST_AFTER_S = 0.5


def anatomy(path: str) -> dict | None:
    import h5py

    with h5py.File(path, "r") as h:
        if "gesture/intended" not in h or len(h["gesture/time"]) < 2:
            return None
        g_time, intended = h["gesture/time"][:], h["gesture/intended"][:]
        p_time, mean = h["policy/time"][:], h["policy/mean"][:]
        c_time, twist, scale = h["command/time"][:], h["command/twist"][:], h["command/speed_scale"][:]
    at = lambda times, t: np.clip(np.searchsorted(times, t), 0, len(times) - 1)
    on_c = np.abs(intended[at(g_time, c_time)]).max(1) > 0
    policy_c = np.linalg.norm(mean[at(p_time, c_time)] / FULL, axis=1)
    command_c = np.linalg.norm(twist / FULL, axis=1)
    moving = on_c & (policy_c > 0.1)

    y = intended[at(g_time, p_time)] / FULL
    out = mean / FULL
    on = np.abs(y).max(1) > 0
    since, previous = np.full(len(p_time), np.inf), np.zeros_like(y)
    until, upcoming = np.full(len(p_time), np.inf), np.zeros_like(y)
    last_t, last_y = -np.inf, np.zeros(6)
    for i in range(len(p_time)):
        if on[i]:
            last_t, last_y = p_time[i], y[i]
        since[i], previous[i] = p_time[i] - last_t, last_y
    next_t, next_y = np.inf, np.zeros(6)
    for i in range(len(p_time) - 1, -1, -1):
        if on[i]:
            next_t, next_y = p_time[i], y[i]
        until[i], upcoming[i] = next_t - p_time[i], next_y
    rest = ~on & (since >= REST_AFTER_S)
    loud = rest & (np.abs(out).max(1) > 0.2)
    cos = lambda a, b: float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b) + 1e-12))
    ways = {"next": 0, "previous": 0, "neither": 0}
    for i in np.nonzero(loud)[0]:
        way = ("next" if cos(out[i], upcoming[i]) > 0.5 else
               "previous" if cos(out[i], previous[i]) > 0.5 else "neither")
        ways[way] += 1
    finite_until = until[loud][np.isfinite(until[loud])]
    return {"speed_scale": np.quantile(scale[on_c], [0.1, 0.5, 0.9]) if on_c.any() else np.full(3, np.nan),
            "command_over_policy": float(np.median(command_c[moving] / policy_c[moving])) if moving.any() else np.nan,
            "rest_steps": int(rest.sum()), "rest_loud": int(loud.sum()), "ways": ways,
            "until_next_s": float(np.median(finite_until)) if finite_until.size else np.nan}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--logs", nargs="+", required=True, help="run logs of a recorded study")
    args = p.parse_args(argv)
    total = {"rest_steps": 0, "rest_loud": 0, "next": 0, "previous": 0, "neither": 0}
    scales, ratios = [], []
    for path in sorted(args.logs):
        a = anatomy(path)
        if a is None:
            continue
        scales.append(a["speed_scale"][1])
        ratios.append(a["command_over_policy"])
        total["rest_steps"] += a["rest_steps"]
        total["rest_loud"] += a["rest_loud"]
        for k, v in a["ways"].items():
            total[k] += v
        q = a["speed_scale"]
        print(f"{pathlib.Path(path).stem}: speed scale in gestures {q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f}; "
              f"command / policy {a['command_over_policy']:.2f}; rest steps over a fifth "
              f"{a['rest_loud']} of {a['rest_steps']} (toward the next gesture {a['ways']['next']}, along the "
              f"previous {a['ways']['previous']}, neither {a['ways']['neither']}; median {a['until_next_s']:.1f} s "
              f"before the next)")
    loud = max(total["rest_loud"], 1)
    print(f"all: median speed scale in gestures {np.nanmedian(scales):.2f}, command / policy "
          f"{np.nanmedian(ratios):.2f}; rest steps over a fifth {total['rest_loud']} of {total['rest_steps']}: "
          f"toward the next gesture {total['next'] / loud:.0%}, along the previous {total['previous'] / loud:.0%}, "
          f"neither {total['neither'] / loud:.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
