"""An encoder of the hand's path and shape, learned across people for the per-person kernel read.

    python -m rtcohand_drake.learning.hand_encoder --data PEOPLE.h5 [MORE.h5 ...] --out encoder.pt
        [--iterations 1200] [--seed 0] [--max-minutes M]

The kernel read of the shipped policy file (`learning.path_shape_policy`) measures how alike
two moments of a hand are by the distance between their raw path-and-shape features
(`hand_features.PathShapeStream`, PATH_SHAPE_DIM numbers). It knows nothing of hands beyond one
person's own clips. This module learns, from the labelled clips of many people, a map of those
features to a short embedding (EMBED_DIM) in which that distance tells a person's gestures apart:

    training, per iteration:  one person of the files, up to `max_clips` of their clips; a random
                              quarter of them are read with the rest as context, by exactly the
                              kernel read (standardised by the context, Gaussian kernel of
                              `bandwidth` x the median distance, `lam` on the diagonal), over the
                              embedding of augmented features; loss = the read's squared error as a
                              share of the labels' (AdamW).
    augmentation:             the hand scaled by exp(0.1 N), turned about the vertical by 0.15 N rad,
                              3 mm of noise on every keypoint coordinate.

The files are any labelled dataset files (docs/interfaces.md): recorded people (each person with
their own command map) or a simulated population. Only the labels (twists) are needed, not gesture
names. Pass the file to `path_shape_policy --encoder` to build a policy file whose kernel read is
over the embedding. The encoder is a TorchScript file (`forward(x [N, PATH_SHAPE_DIM]) -> [N,
EMBED_DIM]`, the standardisation of its training features inside) with a JSON model card naming
what it was trained on: a file built from data that may not be redistributed may not be either.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import time
import warnings
from typing import List, Optional, Sequence, Tuple

import numpy as np
import torch
from torch import nn

from rtcohand_drake.data.hand_features import FEATURE_DIM, PATH_SHAPE_DIM
from rtcohand_drake.errors import InputError, run_cli

EMBED_DIM = 64
HIDDEN = 256
DROPOUT = 0.2
# Chosen on recorded development people (docs/real_people.md, section 6): the kernel read's settings
# are the shipped read's (learning.kernel_reference), the training's below.
ITERATIONS = 1200
LEARNING_RATE = 3e-4
MAX_CLIPS = 48
PEOPLE_PER_STEP = 1
HELD_SHARE = 0.25
SCALE_SIGMA, TURN_SIGMA_RAD, NOISE_M = 0.1, 0.15, 0.003

Person = List[Tuple[np.ndarray, np.ndarray]]  # [(path and shape (T, PATH_SHAPE_DIM), labels (T, 6)), ...]


class HandEncoder(nn.Module):
    """x [N, PATH_SHAPE_DIM] (NaN read as 0) -> embedding [N, EMBED_DIM]; standardised by its training steps."""

    def __init__(self, mean: torch.Tensor, spread: torch.Tensor):
        super().__init__()
        self.register_buffer("mean", mean.to(torch.float32).clone())
        self.register_buffer("spread", spread.to(torch.float32).clone())
        self.input_dim = PATH_SHAPE_DIM
        self.embed_dim = EMBED_DIM
        self.body = nn.Sequential(nn.Linear(PATH_SHAPE_DIM, HIDDEN), nn.ReLU(), nn.Dropout(DROPOUT),
                                  nn.Linear(HIDDEN, HIDDEN), nn.ReLU(), nn.Dropout(DROPOUT),
                                  nn.Linear(HIDDEN, EMBED_DIM))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = torch.nan_to_num(x.to(torch.float32), 0.0, 0.0, 0.0)
        return self.body((x - self.mean) / self.spread)


def augment(x: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Each row of path-and-shape features (lags x 21 x 3, in the user frame) scaled, turned about Z and jittered."""
    b = x.shape[0]
    p = x.reshape(b, -1, 3)
    angle = TURN_SIGMA_RAD * torch.randn(b, generator=gen)
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    p = torch.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1], p[..., 2]], -1)
    p = p * torch.exp(SCALE_SIGMA * torch.randn(b, 1, 1, generator=gen))
    return (p + NOISE_M * torch.randn(p.shape, generator=gen)).reshape(b, -1)


def kernel_read(zc: torch.Tensor, yc: torch.Tensor, zt: torch.Tensor, bandwidth: float, lam: float) -> torch.Tensor:
    """The kernel reference's read of zt from the context (zc, yc), differentiable in zc and zt: standardised
    by the context, width = bandwidth x the median distance between context steps, lam on the diagonal."""
    mean, spread = zc.mean(0), zc.std(0, unbiased=False) + 1e-6
    zc, zt = (zc - mean) / spread, (zt - mean) / spread
    d2 = torch.cdist(zc, zc) ** 2
    apart = d2[d2 > 0]
    width = bandwidth * (apart.sqrt().median().detach() if apart.numel() else torch.ones((), dtype=zc.dtype))
    gram = torch.exp(-d2 / (2 * width ** 2))
    offset = yc.mean(0)
    weights = torch.linalg.solve(gram + lam * torch.eye(len(gram), dtype=gram.dtype), yc - offset)
    return offset + torch.exp(-torch.cdist(zt, zc) ** 2 / (2 * width ** 2)) @ weights


def people_of(paths: Sequence[os.PathLike]) -> List[Person]:
    """Every user's labelled clips in the files, path-and-shape columns only; a file with none is an InputError."""
    from rtcohand_drake.learning.train import load_clips

    people: List[Person] = []
    for path in paths:
        clips = [c for c in load_clips(str(path), 10.0, path_shape=True) if c.labels is not None]
        if not clips:
            raise InputError(f"{path}: no labelled clips to learn from")
        for user in sorted({c.user for c in clips}):
            mine = [(np.nan_to_num(c.features[:, FEATURE_DIM:]).astype(np.float32),
                     np.nan_to_num(c.labels).astype(np.float64)) for c in clips if c.user == user and len(c.features)]
            if len(mine) >= 2:
                people.append(mine)
    if not people:
        raise InputError("the encoder needs people with at least two labelled clips each")
    return people


def _held_out_loss(encoder: HandEncoder, clips: Person, rng: np.random.Generator, gen: torch.Generator,
                   bandwidth: float, lam: float, max_clips: int) -> torch.Tensor:
    """The kernel read's error on a random quarter of the person's clips (at most `max_clips` drawn), read
    with the rest as context, as a share of the labels' squared size."""
    if len(clips) > max_clips:
        clips = [clips[j] for j in rng.choice(len(clips), max_clips, replace=False)]
    held = rng.random(len(clips)) < HELD_SHARE
    if held.all() or not held.any():
        held = np.arange(len(clips)) == rng.integers(len(clips))
    x = torch.from_numpy(np.concatenate([c[0] for c in clips]))
    y = torch.from_numpy(np.concatenate([c[1] for c in clips]))
    target = torch.from_numpy(np.concatenate([np.full(len(c[0]), h) for c, h in zip(clips, held)]))
    z = encoder(augment(x, gen)).to(torch.float64)
    pred = kernel_read(z[~target], y[~target], z[target], bandwidth, lam)
    return ((pred - y[target]) ** 2).mean() / ((y[target] ** 2).mean() + 1e-9)


def train_encoder(people: Sequence[Person], iterations: int = ITERATIONS, seed: int = 0,
                  bandwidth: Optional[float] = None, lam: Optional[float] = None, lr: float = LEARNING_RATE,
                  max_clips: int = MAX_CLIPS, max_minutes: float = 0.0, progress: bool = True,
                  encoder: Optional[HandEncoder] = None, people_per_step: int = PEOPLE_PER_STEP
                  ) -> Tuple[HandEncoder, dict]:
    """Trains (or goes on training) an encoder for the kernel read; returns it in eval mode and a summary.
    Each step's loss is the mean over `people_per_step` people drawn at random."""
    from rtcohand_drake.learning.kernel_reference import BANDWIDTH, LAMBDA

    bandwidth = BANDWIDTH if bandwidth is None else bandwidth
    lam = LAMBDA if lam is None else lam
    if iterations < 1 or not people:
        raise InputError(f"need iterations >= 1 and at least one person, got {iterations} and {len(people)}")
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    if encoder is None:
        steps = torch.from_numpy(np.concatenate([x for person in people for x, _ in person]))
        encoder = HandEncoder(steps.mean(0), steps.std(0) + 1e-3)
    opt = torch.optim.AdamW(encoder.parameters(), lr)
    encoder.train()
    start, losses, done = time.perf_counter(), [], 0
    for i in range(iterations):
        if max_minutes and time.perf_counter() - start > 60.0 * max_minutes:
            break
        loss = torch.zeros((), dtype=torch.float64)
        for _ in range(people_per_step):
            loss = loss + _held_out_loss(encoder, people[rng.integers(len(people))], rng, gen, bandwidth, lam,
                                         max_clips) / people_per_step
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
        done = i + 1
        if progress and done % 100 == 0:
            print(f"  iteration {done}/{iterations}: loss (share of zero twist, last 100) "
                  f"{np.mean(losses[-100:]):.3f}", flush=True)
    encoder.eval()
    return encoder, {"iterations": done, "seed": seed, "bandwidth": bandwidth, "lambda": lam, "lr": lr,
                     "max_clips": max_clips, "people_per_step": people_per_step, "people": len(people), "minutes": (time.perf_counter() - start) / 60.0,
                     "final_loss": float(np.mean(losses[-100:])) if losses else None}


def save_encoder(encoder: HandEncoder, out: os.PathLike, card: dict) -> pathlib.Path:
    """A TorchScript encoder file with its JSON card, written atomically."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.jit")
        scripted = torch.jit.script(encoder.eval())
    card = dict(card, kind="hand_encoder", input_dim=PATH_SHAPE_DIM, embed_dim=EMBED_DIM)
    from rtcohand_drake.learning.export import save_scripted  # export loads the training code; only here

    return save_scripted(scripted, out, card, "encoder_card.json")


def load_encoder(path: os.PathLike) -> Tuple[torch.jit.ScriptModule, dict]:
    """An encoder file and its card; a missing, corrupt or wrong file is an InputError naming it."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such encoder file")
    extra = {"encoder_card.json": ""}
    try:
        module = torch.jit.load(str(path), map_location="cpu", _extra_files=extra)
    except Exception as err:  # torch raises RuntimeError and others for a damaged archive
        raise InputError(f"{path}: not an encoder file ({type(err).__name__})") from None
    if not extra["encoder_card.json"]:
        raise InputError(f"{path}: not an encoder file (no encoder card; build one with "
                         "python -m rtcohand_drake.learning.hand_encoder)")
    card = json.loads(extra["encoder_card.json"])
    if card.get("input_dim") != PATH_SHAPE_DIM or int(getattr(module, "input_dim", -1)) != PATH_SHAPE_DIM:
        raise InputError(f"{path}: the encoder reads {card.get('input_dim')} features, the hand's path and "
                         f"shape are {PATH_SHAPE_DIM}")
    return module, card


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.learning.hand_encoder",
                                description=__doc__.splitlines()[0])
    p.add_argument("--data", nargs="+", required=True, help="labelled dataset files of the people to learn from")
    p.add_argument("--out", required=True, help="the encoder file to write")
    p.add_argument("--iterations", type=int, default=ITERATIONS, help="people drawn, one per step")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-minutes", type=float, default=0.0, help="stop after this long (0: no limit)")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    torch.set_num_threads(max(1, min(2, os.cpu_count() or 1)))
    people = people_of(args.data)
    print(f"learning from {len(people)} people of {len(args.data)} file(s)", flush=True)
    encoder, summary = train_encoder(people, args.iterations, args.seed, max_minutes=args.max_minutes)
    out = save_encoder(encoder, args.out, {"trained_on": [pathlib.Path(d).name for d in args.data], **summary})
    print(f"wrote {out} ({summary['iterations']} iterations in {summary['minutes']:.1f} min, "
          f"last loss {summary['final_loss']:.3f})")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.learning.hand_encoder"))


if __name__ == "__main__":
    entry_point()
