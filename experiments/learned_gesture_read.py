"""Experiment: does a gesture classifier learned across recorded people help a per-person read?

    python experiments/learned_gesture_read.py --root SHREC17_DIR --train-subjects 2 4 8 10 12 14
        --eval-subjects 16 20 22 26 [--epochs 90] [--lam 1.0] [--seed 0] [--out DIR]

A causal classifier (one GRU layer of 96 units over the 36 hand-part
velocities at 10 Hz, normalised, then a linear layer) is trained to name, at
every step, which of the 28 SHREC'17 variants (gesture x one finger / whole
hand) is being made, or rest, on every sequence of the training subjects
(cross-entropy, Adam 2e-3, batch 32, input noise 0.05 in normalised units).
Each evaluation person is then read as the Person setting reads them
(`data.import_shrec17`, natural and custom maps): a ridge regression
(lambda `--lam`, no intercept) of the context's labels on the classifier's 29
per-step probabilities, solved on that person's train clips, applied to their
held-out clips. Beside it, the two per-person references on the same
episodes. Shares of commanding zero twist, as `evaluate` reports them.

The classifier is trained on recorded people, so nothing it produces may be
shipped in this repository (the recordings' terms): this measures a
direction, it builds no product file. The SHREC'17 files are read from
`--root`; nothing is written but DIR/learned_gesture_read.json.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

RATE_HZ = 10.0
CLASSES = 1 + 28  # rest, then (gesture - 1) * 2 + (finger - 1) + 1


def sequence_arrays(q, rest_frames: int = 15):
    """Features (T, 36) and per-step class (T,) of one SHREC'17 sequence, with the importer's rests."""
    from rtcohand_drake.data import import_shrec17 as shrec
    from rtcohand_drake.data.hand_features import hand_features

    kp = shrec.to_user_frame(shrec.read_skeletons(q.path))
    n = len(kp)
    x, _ = hand_features(shrec.with_rest(kp, rest_frames), shrec.FPS, RATE_HZ)
    t = np.arange(n + 2 * rest_frames) / shrec.FPS
    gesture = np.r_[np.zeros(rest_frames), np.ones(n), np.zeros(rest_frames)]
    on = np.interp(np.arange(len(x)) / RATE_HZ, t, gesture) > 0.5
    return x, np.where(on, (q.gesture - 1) * 2 + q.finger, 0)


def train_classifier(sequences, epochs: int, seed: int):
    import torch
    from torch import nn

    torch.manual_seed(seed)
    data = [sequence_arrays(q) for q in sequences]
    scale = np.concatenate([x for x, _ in data]).std(0) + 1e-6
    longest = max(len(x) for x, _ in data)
    X = np.zeros((len(data), longest, 36), np.float32)
    Y = np.full((len(data), longest), -100, np.int64)
    for i, (x, y) in enumerate(data):
        X[i, :len(x)], Y[i, :len(x)] = x / scale, y
    X, Y = torch.from_numpy(X), torch.from_numpy(Y)

    class Classifier(nn.Module):
        def __init__(self):
            super().__init__()
            self.gru = nn.GRU(36, 96, batch_first=True)
            self.head = nn.Linear(96, CLASSES)

        def forward(self, x):
            return self.head(self.gru(x)[0])

    net = Classifier()
    opt = torch.optim.Adam(net.parameters(), 2e-3)
    gen = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        perm = torch.randperm(len(X), generator=gen)
        for b in range(0, len(X), 32):
            idx = perm[b:b + 32]
            xb = X[idx] + 0.05 * torch.randn(X[idx].shape, generator=gen)
            loss = nn.functional.cross_entropy(net(xb).reshape(-1, CLASSES), Y[idx].reshape(-1), ignore_index=-100)
            opt.zero_grad()
            loss.backward()
            opt.step()
    net.eval()

    def probabilities(features: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            x = torch.from_numpy((np.nan_to_num(features) / scale).astype(np.float32))[None]
            return torch.softmax(net(x)[0], -1).numpy().astype(np.float64)

    return probabilities, len(data)


def shares(episodes, probabilities, lam: float, ridge, knn) -> dict:
    from rtcohand_drake.learning.knn_reference import KnnReference
    from rtcohand_drake.learning.ridge_reference import RidgeReference

    reads = {"classifier + ridge read": [], f"ridge {ridge[0]} {ridge[1]:g}": [], f"nearest neighbours {knn[0]} {knn[1]}": []}
    zeros = []
    cache = {}
    for e in episodes:
        key = e.target.user
        if key not in cache:
            P = np.concatenate([probabilities(x) for x, _ in e.context])
            Yc = np.concatenate([y for _, y in e.context]).astype(np.float64)
            cache[key] = np.linalg.solve(P.T @ P + lam * np.eye(CLASSES), P.T @ Yc)
        y = np.asarray(e.target.labels, np.float64)
        preds = [probabilities(e.target_features) @ cache[key],
                 RidgeReference(*ridge).fit(e.context).predict(e.target_features),
                 KnnReference(*knn).fit(e.context).predict(e.target_features)]
        for name, p in zip(reads, preds):
            reads[name].append(np.mean((y - p) ** 2))
        zeros.append(np.mean(y ** 2))
    return {name: float(np.mean(v) / np.mean(zeros)) for name, v in reads.items()}


def main(argv=None) -> int:
    from rtcohand_drake.data import import_shrec17 as shrec
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--root", required=True, type=Path)
    p.add_argument("--train-subjects", type=int, nargs="+", required=True)
    p.add_argument("--eval-subjects", type=int, nargs="+", required=True)
    p.add_argument("--epochs", type=int, default=90)
    p.add_argument("--lam", type=float, default=1.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ridge", nargs=2, type=float, default=[30, 3000])
    p.add_argument("--knn", nargs=2, type=int, default=[20, 20])
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    if set(args.train_subjects) & set(args.eval_subjects):
        raise SystemExit("--train-subjects and --eval-subjects must not share a person")
    start = time.perf_counter()
    train = [q for q in shrec.find_sequences(args.root) if q.subject in args.train_subjects]
    probabilities, n_train = train_classifier(train, args.epochs, args.seed)
    trained_s = time.perf_counter() - start
    result = {"train_subjects": args.train_subjects, "eval_subjects": args.eval_subjects, "epochs": args.epochs,
              "lam": args.lam, "seed": args.seed, "train_sequences": n_train, "train_s": trained_s, "shares": {}}
    ridge = (int(args.ridge[0]), float(args.ridge[1]))
    with tempfile.TemporaryDirectory() as tmp:
        for mapping in shrec.MAPPINGS:
            path = Path(tmp) / f"{mapping}.h5"
            shrec.import_shrec17(args.root, path, mapping, args.eval_subjects, progress=False)
            episodes = evaluation_episodes(load_clips(str(path), RATE_HZ), "Person", 0)
            result["shares"][mapping] = shares(episodes, probabilities, args.lam, ridge, tuple(args.knn))
            print(f"{mapping}: {len(episodes)} held-out clips: " + ", ".join(
                f"{k} {v:.3f}" for k, v in result["shares"][mapping].items()), flush=True)
    print(f"classifier trained on {n_train} sequences of subjects {args.train_subjects} in {trained_s:.0f} s")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "learned_gesture_read.json").write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
