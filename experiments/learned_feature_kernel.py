"""Experiment: a kernel read per person over features of the hand's path and shape learned across people.

    python experiments/learned_feature_kernel.py --root SHREC17_DIR --train-subjects 2 4 8 10 12 14
        --eval-subjects 16 20 22 26 [--epochs 30] [--kernel-iterations 1200] [--people-per-step 1]
        [--train-data SIMULATED.h5 ...] [--seeds 0 1 2] [--bandwidths 0.5 1] [--lams 0.3 1] [--out DIR]

The encoder is `learning.hand_encoder.HandEncoder` (the 315 path-and-shape features, standardised over
the training steps, -> 256 -> 256 -> a 64-wide embedding), trained in up to two stages:

- `--epochs` > 0, on gesture names: the embedding, then ReLU and a linear layer to 29 classes, names at
  every policy step of every sequence of the training subjects which of the 28 SHREC'17 variants
  (gesture x one finger / whole hand) is being made, or rest (cross-entropy, AdamW 1e-3, batch 256,
  the module's augmentation). Recorded gesture names are needed: a dataset file does not carry them.
- `--kernel-iterations` > 0, then, on the kernel read itself (`hand_encoder.train_encoder`, as the
  module's command trains it): the training subjects under the natural map and the custom maps of
  `--custom-seeds` (each a person of their own), and the people of `--train-data` files.

Each evaluation person is then read as the Person setting reads them (`data.import_shrec17`, natural and
custom maps): the kernel reference (`learning.kernel_reference`, bandwidth x the median distance, lambda)
fitted to that person's context clips, over the 64-wide embedding instead of the raw features. Beside
it, the kernel reference on the raw path and shape (the policy file for real hands' read, alone), on the
same episodes. Shares of commanding zero twist, as `evaluate` reports them.

An encoder trained on recorded people may not be shipped in this repository (the recordings' terms):
this measures a direction; it writes no encoder file. The SHREC'17 files are read from `--root`;
nothing is written but DIR/learned_feature_kernel.json.
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
REST_FRAMES = 15  # the importer's rest on each side (0.5 s at 30 frames/s)


def sequence_steps(q):
    """Path-and-shape features (T, 315) and per-step class (T,) of one SHREC'17 sequence, with the importer's rests."""
    from rtcohand_drake.data import import_shrec17 as shrec
    from rtcohand_drake.data.hand_features import path_shape_features

    kp = shrec.to_user_frame(shrec.read_skeletons(q.path))
    n = len(kp)
    x = path_shape_features(shrec.with_rest(kp, REST_FRAMES), shrec.FPS, RATE_HZ)
    t = np.arange(n + 2 * REST_FRAMES) / shrec.FPS
    gesture = np.r_[np.zeros(REST_FRAMES), np.ones(n), np.zeros(REST_FRAMES)]
    on = np.interp(np.arange(len(x)) / RATE_HZ, t, gesture) > 0.5
    return np.nan_to_num(x), np.where(on, (q.gesture - 1) * 2 + q.finger, 0)


def train_classes(steps, epochs: int, seed: int):
    """A `learning.hand_encoder.HandEncoder` whose embedding (then ReLU and a linear layer) is trained to name
    each step's class, on [(x (T, 315), class (T,)), ...] for `epochs` (standardised by their steps).
    Returns it (eval mode) and its training accuracy."""
    import torch
    from torch import nn

    from rtcohand_drake.learning.hand_encoder import HandEncoder, augment

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    X = torch.from_numpy(np.concatenate([x for x, _ in steps]).astype(np.float32))
    Y = torch.from_numpy(np.concatenate([y for _, y in steps]).astype(np.int64))
    encoder = HandEncoder(X.mean(0), X.std(0) + 1e-3)
    head = nn.Sequential(nn.ReLU(), nn.Linear(encoder.embed_dim, CLASSES))
    opt = torch.optim.AdamW([*encoder.parameters(), *head.parameters()], 1e-3)
    for _ in range(epochs):
        encoder.train()
        perm = torch.randperm(len(X), generator=gen)
        for b in range(0, len(X), 256):
            idx = perm[b:b + 256]
            loss = nn.functional.cross_entropy(head(encoder(augment(X[idx], gen))), Y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
    encoder.eval()
    with torch.no_grad():
        accuracy = float((head(encoder(X)).argmax(-1) == Y).float().mean())
    return encoder, accuracy


def embedding(encoder):
    """embed(x (T, 315)) -> (T, 64) float64 of an encoder."""
    import torch

    def embed(x: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return encoder(torch.from_numpy(np.asarray(x, np.float32))).numpy().astype(np.float64)

    return embed


def person_maps(root, subjects, custom_seeds, tmp) -> list:
    """The training subjects' clips under the natural map and the custom maps of each seed: one entry per
    (map, person)."""
    from rtcohand_drake.data import import_shrec17 as shrec
    from rtcohand_drake.learning.hand_encoder import people_of

    people = []
    for mapping, seed in [("natural", 0)] + [("custom", s) for s in custom_seeds]:
        path = Path(tmp) / f"train_{mapping}_{seed}.h5"
        shrec.import_shrec17(root, path, mapping, subjects, seed=seed, progress=False)
        people += people_of([path])
    return people


def shares(episodes, embed, bandwidths, lams) -> dict:
    """Each read's share of the zero twist's squared error over the episodes (the context fitted once per person)."""
    from rtcohand_drake.learning.kernel_reference import KernelReference

    settings = [(b, l) for b in bandwidths for l in lams]
    fits, errors, zeros = {}, {}, []
    for e in episodes:
        user = e.target.user
        if user not in fits:
            ctx = [(np.asarray(x)[:, 36:], y) for x, y in e.context]
            emb = [(embed(x), y) for x, y in ctx]
            fits[user] = {f"raw path and shape b{b:g} l{l:g}": (KernelReference(b, l, start=0).fit(ctx), False)
                          for b, l in settings}
            fits[user].update({f"learned features b{b:g} l{l:g}": (KernelReference(b, l, start=0).fit(emb), True)
                               for b, l in settings})
        x = np.asarray(e.target_features)[:, 36:]
        y = np.nan_to_num(np.asarray(e.target.labels, np.float64))
        zx = embed(x)
        for name, (fit, learned) in fits[user].items():
            errors.setdefault(name, []).append(np.mean((y - fit.predict(zx if learned else x)) ** 2))
        zeros.append(np.mean(y ** 2))
    return {name: float(np.mean(v) / np.mean(zeros)) for name, v in errors.items()}


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data import import_shrec17 as shrec
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.hand_encoder import people_of, train_encoder
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--root", required=True, type=Path)
    p.add_argument("--train-subjects", type=int, nargs="*", default=[],
                   help="recorded people to train on (the classifier, and the kernel read under several maps)")
    p.add_argument("--train-data", nargs="*", default=[],
                   help="dataset files whose people the kernel read is also trained on (e.g. a simulated population)")
    p.add_argument("--eval-subjects", type=int, nargs="+", required=True)
    p.add_argument("--epochs", type=int, default=30)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--bandwidths", type=float, nargs="+", default=[0.5, 1.0])
    p.add_argument("--lams", type=float, nargs="+", default=[0.3, 1.0])
    p.add_argument("--kernel-iterations", type=int, default=0,
                   help="then train the encoder for the kernel read itself, this many (map, person) draws")
    p.add_argument("--people-per-step", type=int, default=1, help="people averaged in each kernel training step")
    p.add_argument("--custom-seeds", type=int, nargs="+", default=list(range(8)),
                   help="the training people's custom maps for --kernel-iterations (with the natural map)")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    if set(args.train_subjects) & set(args.eval_subjects):
        raise SystemExit("--train-subjects and --eval-subjects must not share a person")
    if not ((args.epochs and args.train_subjects) or args.kernel_iterations):
        raise SystemExit("nothing to train: give --train-subjects and --epochs, or --kernel-iterations")
    torch.set_num_threads(1)
    start = time.perf_counter()
    steps = [sequence_steps(q) for q in shrec.find_sequences(args.root) if q.subject in args.train_subjects]
    with tempfile.TemporaryDirectory() as tmp:
        episodes = {}
        for mapping in shrec.MAPPINGS:
            path = Path(tmp) / f"{mapping}.h5"
            shrec.import_shrec17(args.root, path, mapping, args.eval_subjects, progress=False)
            episodes[mapping] = evaluation_episodes(load_clips(str(path), RATE_HZ, path_shape=True), "Person", 0)
        people = []
        if args.kernel_iterations:
            people = person_maps(args.root, args.train_subjects, args.custom_seeds, tmp) if args.train_subjects else []
            if args.train_data:
                people += people_of(args.train_data)
    result = {"train_subjects": args.train_subjects, "train_data": args.train_data, "eval_subjects": args.eval_subjects, "epochs": args.epochs,
              "kernel_iterations": args.kernel_iterations, "train_sequences": len(steps), "train_steps": int(sum(len(x) for x, _ in steps)), "seeds": {}}
    for seed in args.seeds:
        t0 = time.perf_counter()
        if args.epochs and steps:
            encoder, accuracy = train_classes(steps, args.epochs, seed)
        else:
            encoder, accuracy = None, None
        if args.kernel_iterations:
            encoder, _ = train_encoder(people, args.kernel_iterations, seed, args.bandwidths[0], args.lams[0],
                                       encoder=encoder, people_per_step=args.people_per_step)
        embed = embedding(encoder)
        run = {"train_s": time.perf_counter() - t0, "train_accuracy": accuracy, "shares": {}}
        print(f"seed {seed}: encoder trained in {run['train_s']:.0f} s (classes: {len(steps) if args.epochs else 0} "
              f"sequences, training accuracy {accuracy}; kernel read: {len(people)} people, "
              f"{args.kernel_iterations} steps)", flush=True)
        for mapping, eps in episodes.items():
            run["shares"][mapping] = shares(eps, embed, args.bandwidths, args.lams)
            print(f"  {mapping}: {len(eps)} held-out clips: " + ", ".join(
                f"{k} {v:.3f}" for k, v in run["shares"][mapping].items()), flush=True)
        result["seeds"][str(seed)] = run
    print(f"total {time.perf_counter() - start:.0f} s")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "learned_feature_kernel.json").write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
