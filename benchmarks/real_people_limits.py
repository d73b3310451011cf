"""What limits a read of recorded people: where the error sits, and what a perfect classifier would score.

    python benchmarks/real_people_limits.py --data FILE.h5 [--ridge 30 3000] [--knn 20 20] [--out DIR]

On the Person setting of an imported file (`data.import_shrec17`: each
person's held-out clips, their other clips as context), all as a share of
commanding zero twist, the metric of `evaluate`:

- **late oracle**: a read that knows the held-out clip's command exactly, but
  only `d` seconds after its label starts, and commands zero before: the
  price of the time any causal read needs to tell gestures apart;
- **where the error sits**, for each per-person reference: before the
  gesture, in its first 0.5 s, later in the gesture, and after it;
- **whole-gesture nearest neighbour**: the share of held-out clips whose
  nearest context clip has the same command, described two ways, both
  resampled to 15 points of the gesture after a 5-frame median filter of
  the raw keypoints: the hand's path (the mean of the 21 keypoints from the
  gesture's start), and the path with the hand's shape (the 21 keypoints
  about their mean, in the user frame). It sees the whole gesture at once,
  so it tells what the hand data say about the gesture, not what a causal
  read can do in time.

- **a nearest-neighbour read of the hand's path and shape**: the
  nearest-neighbour reference again, causal, at the policy's rate, but on
  the keypoints instead of the 36 hand-part velocities: at each step, the
  21 keypoints (the median of each frame and the 4 before) now and 0.4, 0.8, 1.2 and 1.6 s
  before, all about the hand's centre now (k = 5; lags and k chosen on the
  development people). What the policy's input leaves out: the hand's
  shape, and where it is against where it was;
- **a ridge read of the hand's path and shape**: the same features,
  standardised by the person's context, read linearly (lambda chosen on the
  development people): whether a linear read, as the policy's, gains from
  the hand's shape;
- **a kernel ridge read of the hand's path and shape**: the same features
  under a Gaussian kernel (bandwidth and lambda chosen on the development
  people): a nonlinear read of the kind of the paper's attention.

Writes DIR/real_people_limits.json when --out is given.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

DELAYS_S = (0.3, 0.5, 0.8)
RATE_HZ = 10.0
EARLY_S = 0.5


def late_oracle(episodes, delay_s: float) -> float:
    errors, zeros = [], []
    for e in episodes:
        y = np.asarray(e.target.labels, np.float64)
        pred = np.zeros_like(y)
        on = np.flatnonzero(np.abs(y).sum(1) > 0)
        if on.size:
            start = on[0] + int(round(delay_s * RATE_HZ))
            pred[start:] = y[start:]
        errors.append(np.mean((y - pred) ** 2))
        zeros.append(np.mean(y ** 2))
    return float(np.mean(errors) / np.mean(zeros))


def error_by_phase(episodes, make) -> dict:
    parts = dict.fromkeys(("before", "first 0.5 s", "later in the gesture", "after"), 0.0)
    zero = 0.0
    early = int(round(EARLY_S * RATE_HZ))
    for e in episodes:
        y = np.asarray(e.target.labels, np.float64)
        err = ((y - make().fit(e.context).predict(e.target_features)) ** 2).sum(1) / y.size
        on = np.flatnonzero(np.abs(y).sum(1) > 0)
        a, b = on[0], on[-1]
        parts["before"] += err[:a].sum()
        parts["first 0.5 s"] += err[a:a + early].sum()
        parts["later in the gesture"] += err[a + early:b + 1].sum()
        parts["after"] += err[b + 1:].sum()
        zero += np.mean(y ** 2)
    return {k: float(v / zero) for k, v in parts.items()}


def hand_path(clip, points: int = 15, shape: bool = False) -> np.ndarray:
    """The gesture's path (points x 3), and with `shape` the hand's shape about its centre (points x 63)."""
    on = np.flatnonzero(np.abs(clip.object_velocity).max(1) > 0)
    kp = np.asarray(clip.keypoints[on[0]:on[-1] + 1], np.float64)
    kp = np.stack([np.median(kp[max(0, i - 2):i + 3], 0) for i in range(len(kp))])
    at = np.linspace(0, len(kp) - 1, points).round().astype(int)
    centre = kp.mean(1)
    path = (centre - centre[0])[at].reshape(-1)
    if not shape:
        return path
    return np.concatenate([path, (kp - centre[:, None])[at].reshape(-1)])


def command_of(clip) -> tuple[int, int]:
    total = np.asarray(clip.object_velocity, np.float64).sum(0)
    d = int(np.argmax(np.abs(total)))
    return d, int(np.sign(total[d]))


def whole_gesture_accuracy(path: Path, shape: bool = False) -> float:
    from rtcohand_drake.data.dataset import read_dataset

    clips = [c for c in read_dataset(path) if c.object_velocity is not None]
    hits = []
    for user in sorted({c.user for c in clips}):
        train = [c for c in clips if c.user == user and c.split == "train"]
        test = [c for c in clips if c.user == user and c.split == "test"]
        if not train:
            continue
        keys = np.stack([hand_path(c, shape=shape) for c in train])
        for c in test:
            nearest = train[int(np.argmin(((keys - hand_path(c, shape=shape)) ** 2).sum(1)))]
            hits.append(command_of(nearest) == command_of(c))
    return float(np.mean(hits))


TRAJECTORY_LAGS = (0, 4, 8, 12, 16)  # policy steps
TRAJECTORY_K = 5


def hand_trajectory(clip, steps: int) -> np.ndarray:
    """(steps, 63 x lags): the filtered keypoints at each policy step and TRAJECTORY_LAGS before, about
    the hand's centre at that step. The filter is causal: the median of each frame and the 4 before."""
    from rtcohand_drake.data.dataset import resample

    kp = np.asarray(clip.keypoints, np.float64)
    kp = np.stack([np.median(kp[max(0, i - 4):i + 1], 0) for i in range(len(kp))])
    at_rate, _ = resample(kp.reshape(len(kp), -1), clip.times, RATE_HZ)
    at_rate = at_rate[:steps].reshape(-1, 21, 3)
    centre = at_rate.mean(1)[:, None]
    n = len(at_rate)
    return np.concatenate([(at_rate[np.maximum(np.arange(n) - lag, 0)] - centre).reshape(n, -1)
                           for lag in TRAJECTORY_LAGS], 1)


def _person_trajectories(path: Path):
    """Per person with context: (context [(trajectory, labels)], held-out [(trajectory, labels)])."""
    from rtcohand_drake.data.dataset import read_dataset, to_policy_clip

    clips = [c for c in read_dataset(path) if c.object_velocity is not None]

    def described(c):
        y = np.nan_to_num(to_policy_clip(c, RATE_HZ).labels.astype(np.float64))
        return hand_trajectory(c, len(y)), y

    for user in sorted({c.user for c in clips}):
        train = [described(c) for c in clips if c.user == user and c.split == "train"]
        if train:
            yield train, [described(c) for c in clips if c.user == user and c.split == "test"]


def _read_share(path: Path, fit) -> float:
    """The share of zero twist of a read fitted to each person's context, on the Person protocol.

    `fit(features, labels)` gets the person's context steps and returns `predict(features)`."""
    error = zero = 0.0
    for train, test in _person_trajectories(path):
        predict = fit(np.concatenate([x for x, _ in train]), np.concatenate([y for _, y in train]))
        for x, y in test:
            error += np.mean((predict(x) - y) ** 2)
            zero += np.mean(y ** 2)
    return float(error / zero)


def _standardiser(x: np.ndarray):
    """Scales features by the context's mean and spread."""
    mean, std = x.mean(0), x.std(0) + 1e-6
    return lambda a: (a - mean) / std


def trajectory_knn_share(path: Path) -> float:
    """The share of zero twist of the path-and-shape nearest-neighbour read, on the Person protocol."""
    import torch

    def fit(x, y):
        keys = torch.from_numpy(x)

        def predict(a):
            nearest = torch.topk(torch.cdist(torch.from_numpy(a), keys), min(TRAJECTORY_K, len(keys)),
                                 largest=False).indices.numpy()
            return y[nearest].mean(1)
        return predict

    return _read_share(path, fit)


TRAJECTORY_RIDGE_LAMBDA = 1000.0  # chosen on the development people (1, 3, 10, ..., 100000)


def trajectory_ridge_share(path: Path, lam: float = TRAJECTORY_RIDGE_LAMBDA) -> float:
    """The share of zero twist of a ridge read of the same path-and-shape features, fitted to each person:
    a linear read, as the policy's own, on an input that carries the hand's shape. The features are
    standardised by the person's context; lambda is on that scale; the bias is not penalised."""
    def fit(x, y):
        scale = _standardiser(x)

        def design(a):
            return np.hstack([scale(a), np.ones((len(a), 1))])
        d = design(x)
        penalty = lam * np.eye(d.shape[1])
        penalty[-1, -1] = 0.0
        weights = np.linalg.solve(d.T @ d + penalty, d.T @ y)
        return lambda a: design(a) @ weights

    return _read_share(path, fit)


TRAJECTORY_KERNEL = (0.5, 0.3)  # (bandwidth / median distance, lambda), chosen on the development people
# (bandwidths 0.25-1.0 x the median distance, lambda 0.1-10)


def trajectory_kernel_share(path: Path, scale: float = TRAJECTORY_KERNEL[0], lam: float = TRAJECTORY_KERNEL[1]) -> float:
    """The share of zero twist of a kernel ridge read of the same path-and-shape features, fitted to each
    person: a Gaussian kernel over the features standardised by the person's context, its bandwidth
    `scale` times the median distance between the context's steps; the labels' context mean is the
    read with no evidence (a read of the kind of the paper's attention, nonlinear in the features)."""
    return _read_share(path, lambda x, y: kernel_ridge_fit(x, y, scale, lam))


def kernel_ridge_fit(x: np.ndarray, y: np.ndarray, scale: float = TRAJECTORY_KERNEL[0],
                     lam: float = TRAJECTORY_KERNEL[1], standardise: bool = True):
    """`predict(features)` of the kernel reference (`learning.kernel_reference`) fitted to (x, y), reading
    every column of x."""
    from rtcohand_drake.learning.kernel_reference import KernelReference

    return KernelReference(scale, lam, start=0, standardise=standardise).fit([(x, y)]).predict


def main(argv=None) -> int:
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.knn_reference import KnnReference
    from rtcohand_drake.learning.ridge_reference import RidgeReference
    from rtcohand_drake.learning.train import load_clips
    from rtcohand_drake.repo_paths import repo_relative

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, type=Path)
    p.add_argument("--ridge", nargs=2, type=float, default=[30, 3000], metavar=("WINDOW", "LAMBDA"))
    p.add_argument("--knn", nargs=2, type=int, default=[20, 20], metavar=("WINDOW", "K"))
    p.add_argument("--trajectory-lambda", type=float, default=TRAJECTORY_RIDGE_LAMBDA,
                   help="the path-and-shape ridge's lambda (on features standardised by the person's context)")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    episodes = evaluation_episodes(load_clips(str(args.data), RATE_HZ), "Person", 0)
    if not episodes:
        raise SystemExit(f"{args.data}: no Person episodes (clips of split 'test' with 'train' clips of the same user)")
    result = {
        "data": repo_relative(args.data), "episodes": len(episodes),  # the results file is committed
        "late_oracle": {f"{d:g} s": late_oracle(episodes, d) for d in DELAYS_S},
        "error_by_phase": {
            f"ridge {int(args.ridge[0])} {args.ridge[1]:g}": error_by_phase(
                episodes, lambda: RidgeReference(int(args.ridge[0]), args.ridge[1])),
            f"nearest neighbours {args.knn[0]} {args.knn[1]}": error_by_phase(
                episodes, lambda: KnnReference(*args.knn)),
        },
        "whole_gesture_nearest_neighbour_accuracy": whole_gesture_accuracy(args.data),
        "whole_gesture_nearest_neighbour_accuracy_with_shape": whole_gesture_accuracy(args.data, shape=True),
        "path_and_shape_nearest_neighbours": trajectory_knn_share(args.data),
        "path_and_shape_ridge": trajectory_ridge_share(args.data, args.trajectory_lambda),
        "path_and_shape_kernel": trajectory_kernel_share(args.data),
    }
    print(f"{args.data}: {len(episodes)} held-out clips")
    print("late oracle (share of zero twist): " + ", ".join(
        f"knows the command {k} after the label starts {v:.3f}" for k, v in result["late_oracle"].items()))
    for name, parts in result["error_by_phase"].items():
        print(f"{name}: total {sum(parts.values()):.3f} = " + " + ".join(f"{v:.3f} {k}" for k, v in parts.items()))
    print(f"nearest neighbours of the hand's path and shape (k {TRAJECTORY_K}): "
          f"{result['path_and_shape_nearest_neighbours']:.3f} of zero twist")
    print(f"ridge on the hand's path and shape (lambda {args.trajectory_lambda:g}): "
          f"{result['path_and_shape_ridge']:.3f} of zero twist")
    print(f"kernel ridge on the hand's path and shape (bandwidth {TRAJECTORY_KERNEL[0]:g} x the median distance, "
          f"lambda {TRAJECTORY_KERNEL[1]:g}): {result['path_and_shape_kernel']:.3f} of zero twist")
    print(f"whole-gesture nearest neighbour names the command of "
          f"{100 * result['whole_gesture_nearest_neighbour_accuracy']:.0f} % of the held-out clips by the hand's path, "
          f"{100 * result['whole_gesture_nearest_neighbour_accuracy_with_shape']:.0f} % by its path and shape")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "real_people_limits.json").write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
