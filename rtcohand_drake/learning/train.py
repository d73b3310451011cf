"""Train CCHP or a baseline (RANP, Dummy LSTM) on a gesture dataset file.

    python -m rtcohand_drake.train --data PATH.h5 --out DIR [--model cchp|ranp|lstm]
        [--steps N] [--seed S] [--tf-schedule curriculum|fixed:P] [--p-d 0.5] [--p-u 0.5] ...

Also runs under `torchrun --nproc_per_node N -m rtcohand_drake.train ...` with
DistributedDataParallel (gloo on CPU, nccl on GPU): the global batch is split
over the processes, rank 0 writes the checkpoint, history and figure.

Writes DIR/checkpoint.pt (every --checkpoint-every steps and at the end),
DIR/best.pt (the model at the validation with the lowest MSE so far: early
stopping), DIR/history.json and DIR/training_curve.png.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import pathlib
import sys
import typing
import time
from dataclasses import asdict, dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch
from torch import nn

from rtcohand_drake.errors import InputError, run_cli
from rtcohand_drake.learning.batching import Batch, collate
from rtcohand_drake.learning.checkpoint import MODEL_KINDS, build_model, save_checkpoint


@dataclass
class TrainConfig:
    """Training hyperparameters (defaults: paper, "Model Training" appendix and
    "Baselines, Ablations, and Evaluation Metrics"); saved into the checkpoint."""

    model: str = "cchp"
    steps: int = 4000
    batch_size: int = 32  # global, split over DDP processes
    lr: float = 5e-4  # Adam
    seed: int = 0
    tf_schedule: str = "curriculum"  # "curriculum" or "fixed:P"
    tf_start: float = 0.9  # curriculum: p_TF held here ...
    tf_hold_steps: int = 600  # ... for this many steps, then decays linearly ...
    tf_end: float = 0.0  # ... to this value at the last step (or after tf_decay_steps)
    tf_decay_steps: int = 0  # length of the linear decay; 0: it ends at the last step
    p_d: float = 0.5  # probability that the chosen context clip has the target's active dimensions
    p_u: float = 0.5  # probability that it comes from the target's user
    n_random: int = 2  # further random context clips per target
    n_user: int = 0  # further context clips from the target's own user (0: the paper's sampler)
    t_min: int = 10  # minimum length of a context slice cut from the target itself
    p_cxt: float = 0.5  # that slice ends within this fraction of the target
    # Input noise N(0, 1e-6) read as a variance: std 1e-3, in the features' units.
    x_noise_std: float = 1e-3
    # 0: the paper's plain -ELBO. 1.0: beta-NLL weighting (see likelihood_terms), which
    # fits the mean far faster at a CPU budget; the reported ELBO loss is always plain.
    nll_beta: float = 1.0
    # CCHP only: weight of the context-read loss (cchp_elbo's readout_weight); 0: the paper's objective.
    readout_weight: float = 0.0
    rate_hz: float = 10.0
    checkpoint_every: int = 500
    validate_every: int = 250
    validation_episodes: int = 64
    log_every: int = 10
    threads: int = 1  # torch intra-op threads per process (0: torch default); the step loop is overhead-bound
    max_minutes: float = 0.0  # stop early (and save) after this wall time; 0: no limit
    # Start from this checkpoint's weights (a model of the same kind whose parameters have the same
    # names and shapes, for example one trained without a parameter-free option); "": from scratch.
    init_from: str = ""

    def p_tf(self, step: int) -> float:
        """Teacher-forcing probability at a step (0-based)."""
        if self.tf_schedule.startswith("fixed:"):
            return float(self.tf_schedule.split(":", 1)[1])
        if step < self.tf_hold_steps:
            return self.tf_start
        span = self.tf_decay_steps if self.tf_decay_steps > 0 else self.steps - self.tf_hold_steps
        span = max(1, span)
        frac = min(1.0, (step - self.tf_hold_steps) / span)
        return self.tf_start + (self.tf_end - self.tf_start) * frac


def parse_tf_schedule(text: str) -> str:
    if text == "curriculum":
        return text
    if text.startswith("fixed:"):
        try:
            p = float(text.split(":", 1)[1])
        except ValueError:
            p = -1.0
        if 0.0 <= p <= 1.0:
            return text
    raise argparse.ArgumentTypeError(f"expected 'curriculum' or 'fixed:P' with 0 <= P <= 1, got {text!r}")


# --------------------------------------------------------------------------- data


def load_clips(path: str, rate_hz: float, path_shape: bool = False) -> list:
    """Policy-rate clips of a dataset file (`to_policy_clip`); a broken file is an InputError naming it."""
    from rtcohand_drake.data.dataset import DatasetError, load_policy_clips

    try:
        clips = load_policy_clips(path, rate_hz=rate_hz, path_shape=path_shape)
    except DatasetError as err:
        raise InputError(str(err)) from None
    return clips


def training_clips(clips: Sequence, path: str) -> list:
    """Labelled in-sample clips of the train split (the paper's D_train)."""
    train = [c for c in clips if c.labels is not None and c.split == "train" and c.group == "in-sample"]
    if not train:
        train = [c for c in clips if c.labels is not None and c.split == "train"]
    if not train:
        raise InputError(f"{path}: no labelled clips with split 'train' to train on")
    return train


def data_scales(clips: Sequence) -> tuple:
    """Per-channel standard deviations of features and labels over the training steps."""
    feats = np.concatenate([np.nan_to_num(c.features[c.valid]) for c in clips], 0)
    labels = np.concatenate([c.labels for c in clips], 0)
    f_scale = feats.std(0) if len(feats) > 1 else np.ones(36)
    l_scale = labels.std(0) if len(labels) > 1 else np.ones(6)
    # Channels that barely move in the training data keep a floor relative to the busiest ones.
    f_scale = np.maximum(f_scale, 1e-2 * max(f_scale.max(), 1e-6))
    l_scale = np.maximum(l_scale, 1e-2 * max(l_scale.max(), 1e-6))
    return torch.tensor(f_scale, dtype=torch.float32), torch.tensor(l_scale, dtype=torch.float32)


def make_batch(targets: Sequence, pool: Sequence, rng: np.random.Generator, cfg: TrainConfig) -> Batch:
    from rtcohand_drake.data.sampling import sample_context

    contexts = [
        sample_context(t, pool, rng, p_d=cfg.p_d, p_u=cfg.p_u, n_random=cfg.n_random, t_min=cfg.t_min, p_cxt=cfg.p_cxt,
                       n_user=cfg.n_user)
        for t in targets
    ]
    return collate([(t.features, t.labels) for t in targets], contexts)


def validation_batch(clips: Sequence, cfg: TrainConfig) -> Optional[Batch]:
    """A fixed (D+,U+) batch of held-out in-sample clips, for the training curve."""
    from rtcohand_drake.data.sampling import evaluation_episodes

    try:
        episodes = evaluation_episodes(clips, "D+U+", seed=12345)
    except Exception:  # a dataset without test clips for this setting
        return None
    episodes = episodes[: cfg.validation_episodes]
    if not episodes:
        return None
    return collate([(e.target.features, e.target.labels) for e in episodes], [e.context for e in episodes])


# --------------------------------------------------------------------------- distributed


def init_distributed() -> tuple:
    """(rank, world_size, device); initialises the process group under torchrun.

    One process trains on the GPU when torch sees one, else on the CPU."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, torch.device("cuda") if torch.cuda.is_available() else torch.device("cpu")
    import torch.distributed as dist

    use_cuda = torch.cuda.is_available()
    backend = "nccl" if use_cuda else "gloo"
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    device = torch.device("cuda", local_rank) if use_cuda else torch.device("cpu")
    if use_cuda:
        torch.cuda.set_device(device)
    dist.init_process_group(backend=backend)
    return dist.get_rank(), dist.get_world_size(), device


# --------------------------------------------------------------------------- training


def init_from_checkpoint(model: nn.Module, path: str) -> None:
    """Load a checkpoint's (or an exported CCHP policy's) learned weights into `model` (the data's
    normalisation scales are kept)."""
    from rtcohand_drake.learning.checkpoint import load_model_file

    source, payload = load_model_file(path)
    if payload["kind"] != getattr(model, "kind", None):
        raise InputError(f"{path}: --init-from needs a {model.kind} checkpoint, this one holds {payload['kind']!r}")
    state = {k: v for k, v in source.state_dict().items() if not k.startswith("normalizer.")}
    try:
        model.load_state_dict(state, strict=False)
    except RuntimeError as err:
        raise InputError(f"{path}: its weights do not fit this model ({str(err).splitlines()[0]})") from None
    missing = set(model.state_dict()) - set(state) - {k for k in model.state_dict() if k.startswith("normalizer.")}
    if missing:
        raise InputError(f"{path}: it has no weights for {', '.join(sorted(missing)[:3])}")


def train(cfg: TrainConfig, data: str, out: str, model_config: Optional[Dict] = None, quiet: bool = False) -> Dict:
    """Train and return the history. Rank 0 writes the outputs under `out`."""
    rank, world, device = init_distributed()
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    clips = load_clips(data, cfg.rate_hz)
    train_clips = training_clips(clips, data)
    model = build_model(cfg.model, model_config)
    f_scale, l_scale = data_scales(train_clips)
    model.normalizer.set_scales(f_scale, l_scale)
    if cfg.init_from:
        init_from_checkpoint(model, cfg.init_from)
    model.to(device)
    net: nn.Module = model
    if world > 1:
        # The Bayesian linear read leaves the attention's projection unused.
        net = nn.parallel.DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None,
                                                  find_unused_parameters=getattr(model, "blr", None) is not None)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    order_rng = np.random.default_rng(cfg.seed)  # the same on every rank: one global order
    context_rng = np.random.default_rng([cfg.seed, rank])
    generator = torch.Generator(device=device).manual_seed(cfg.seed * 1000 + rank)
    per_rank = max(1, math.ceil(cfg.batch_size / world))
    val_batch = validation_batch(clips, cfg) if rank == 0 else None
    out_dir = pathlib.Path(out)
    if rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    history: Dict[str, List] = {"step": [], "loss": [], "nll": [], "kl": [], "mse": [], "p_tf": [], "time_s": [],
                                "val_step": [], "val_mse": [], "val_loss": []}
    order: List[int] = []
    start = time.perf_counter()
    progress = None
    if rank == 0 and not quiet:
        from tqdm import tqdm

        progress = tqdm(total=cfg.steps, desc=f"train {cfg.model}", mininterval=5.0, file=sys.stderr)
    acc = {"loss": 0.0, "nll": 0.0, "kl": 0.0, "mse": 0.0, "n": 0}
    step = 0
    samples = 0
    for step in range(cfg.steps):
        need = per_rank * world
        while len(order) < need:
            order.extend(order_rng.permutation(len(train_clips)).tolist())
        chunk, order = order[:need], order[need:]
        targets = [train_clips[i] for i in chunk[rank::world]]
        batch = make_batch(targets, train_clips, context_rng, cfg).to(device)
        p_tf = cfg.p_tf(step)
        net.train()
        extra = {"readout_weight": cfg.readout_weight} if cfg.readout_weight > 0.0 else {}
        terms = net(batch, p_tf=p_tf, sample_posterior=True, generator=generator, x_noise_std=cfg.x_noise_std,
                    nll_beta=cfg.nll_beta, **extra)
        optimizer.zero_grad(set_to_none=True)
        terms["loss"].backward()
        optimizer.step()
        samples += need
        for k in ("loss", "nll", "kl", "mse"):
            acc[k] += float(terms["elbo_loss" if k == "loss" else k].detach())
        acc["n"] += 1
        if rank == 0:
            if progress is not None:
                progress.update(1)
            if (step + 1) % cfg.log_every == 0 or step + 1 == cfg.steps:
                n = acc["n"]
                history["step"].append(step + 1)
                for k in ("loss", "nll", "kl", "mse"):
                    history[k].append(acc[k] / n)
                history["p_tf"].append(p_tf)
                history["time_s"].append(time.perf_counter() - start)
                if progress is not None:
                    progress.set_postfix(loss=f"{acc['loss'] / n:.1f}", mse=f"{acc['mse'] / n:.4f}", p_tf=f"{p_tf:.2f}")
                acc = {"loss": 0.0, "nll": 0.0, "kl": 0.0, "mse": 0.0, "n": 0}
            if val_batch is not None and ((step + 1) % cfg.validate_every == 0 or step + 1 == cfg.steps):
                v = validate(model, val_batch.to(device))
                history["val_step"].append(step + 1)
                history["val_mse"].append(v["mse"])
                history["val_loss"].append(v["loss"])
                if v["mse"] <= min(history["val_mse"]):  # early stopping: keep the best validated model
                    _save(model, cfg, step + 1, history, out_dir, data, start, samples, world, name="best.pt")
            if (step + 1) % cfg.checkpoint_every == 0:
                _save(model, cfg, step + 1, history, out_dir, data, start, samples, world)
        if cfg.max_minutes > 0 and time.perf_counter() - start > 60.0 * cfg.max_minutes:
            stop = torch.tensor([1.0])
        else:
            stop = torch.tensor([0.0])
        if world > 1:
            import torch.distributed as dist

            dist.all_reduce(stop)  # every rank stops at the same step
        if stop.item() > 0:
            break
    if progress is not None:
        progress.close()
    if rank == 0:
        _save(model, cfg, step + 1, history, out_dir, data, start, samples, world)
        (out_dir / "history.json").write_text(json.dumps(history, indent=1))
        plot_history(history, out_dir / "training_curve.png", title=f"{cfg.model}, seed {cfg.seed}")
    if world > 1:
        import torch.distributed as dist

        dist.barrier()
        dist.destroy_process_group()
    return history


@torch.no_grad()
def validate(model: nn.Module, batch: Batch) -> Dict[str, float]:
    """Free-running (no teacher forcing) loss and MSE of the mean with z from q(z|C)."""
    model.eval()
    g = torch.Generator(device=batch.y.device).manual_seed(0)
    terms = model(batch, p_tf=0.0, sample_posterior=True, generator=g)
    pred = model.predict(batch)
    m = batch.mask.to(pred["mean"].dtype)
    mse = ((((batch.y - pred["mean"]) ** 2).mean(-1) * m).sum(1) / m.sum(1).clamp_min(1)).mean()
    model.train()
    return {"loss": float(terms["loss"]), "mse": float(mse)}


def _save(model, cfg, step, history, out_dir, data, start, samples, world, name="checkpoint.pt") -> None:
    elapsed = time.perf_counter() - start
    meta = {
        "data": str(data),
        "train_time_s": elapsed,
        "samples_per_s": samples / max(elapsed, 1e-9),
        "world_size": world,
        "threads": torch.get_num_threads(),
        "torch": torch.__version__,
    }
    save_checkpoint(out_dir / name, model, asdict(cfg), step, history, meta)


def plot_history(history: Dict[str, List], path: pathlib.Path, title: str = "") -> None:
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone

    fig = Figure(figsize=(9, 3.2))
    axes = fig.subplots(1, 2)
    if history["step"]:
        axes[0].plot(history["step"], history["loss"], lw=0.8, label="train -ELBO (teacher forcing)")
        if history["val_step"]:
            axes[0].plot(history["val_step"], history["val_loss"], "o-", ms=3, label="validation -ELBO (free-running)")
        axes[0].set_xlabel("step")
        axes[0].set_ylabel("loss per clip")
        axes[0].legend(fontsize=7)
        axes[1].plot(history["step"], history["mse"], lw=0.8, label="train MSE")
        if history["val_step"]:
            axes[1].plot(history["val_step"], history["val_mse"], "o-", ms=3, label="validation MSE (D+U+)")
        ax2 = axes[1].twinx()
        ax2.plot(history["step"], history["p_tf"], "k:", lw=0.8)
        ax2.set_ylabel("p_TF (dotted)")
        ax2.set_ylim(0, 1)
        axes[1].set_yscale("log")
        axes[1].set_xlabel("step")
        axes[1].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


# --------------------------------------------------------------------------- CLI


# Help texts of the flags that need more than their name; every TrainConfig field is a flag.
_FLAG_HELP = {
    "tf_schedule": "'curriculum' (hold --tf-start for --tf-hold-steps, then linear decay to --tf-end) or 'fixed:P'",
    "tf_decay_steps": "steps of the linear decay after the hold; 0 (default): it ends at the last step",
    "n_user": "further context clips from the target's own user, as in deployment (0: the paper's sampler)",
    "nll_beta": "0: the paper's plain -ELBO; >0: beta-NLL weighting of the likelihood term",
    "readout_weight": "CCHP: weight of a loss on the context read r(t) itself predicting the twist (0: off)",
    "threads": "torch threads per process (0: default)",
    "max_minutes": "stop and save after this wall time",
    "init_from": "start from this checkpoint's (or exported CCHP policy's) weights (same model kind and parameter shapes)",
}
_FLAG_TYPE = {"tf_schedule": parse_tf_schedule}


def make_parser() -> argparse.ArgumentParser:
    """--data, --out, then one flag per TrainConfig field (--batch-size for batch_size), then the model's."""
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.train", description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="gesture dataset file (docs/interfaces.md, the gesture dataset file)")
    p.add_argument("--out", required=True, help="output folder")
    hints = typing.get_type_hints(TrainConfig)
    for field in dataclasses.fields(TrainConfig):
        kwargs = {"default": field.default, "help": _FLAG_HELP.get(field.name)}
        if field.name == "model":
            kwargs["choices"] = sorted(MODEL_KINDS)
        else:
            kwargs["type"] = _FLAG_TYPE.get(field.name, hints[field.name])
        p.add_argument("--" + field.name.replace("_", "-"), **kwargs)
    p.add_argument("--model-config", default=None,
                   help="JSON object overriding model sizes, e.g. '{\"attention_heads\": 6}'")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    if args.steps < 1:
        raise InputError(f"--steps must be >= 1, got {args.steps}")
    for name in ("p_d", "p_u", "p_cxt"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            raise InputError(f"--{name.replace('_', '-')} must be in [0, 1], got {getattr(args, name)}")
    if args.readout_weight < 0.0 or (args.readout_weight > 0.0 and args.model != "cchp"):
        raise InputError(f"--readout-weight must be >= 0 and is for --model cchp only, got {args.readout_weight} "
                         f"with --model {args.model}")
    model_config = None
    if args.model_config:
        try:
            model_config = json.loads(args.model_config)
            if not isinstance(model_config, dict):
                raise ValueError("not an object")
        except ValueError as err:
            raise InputError(f"--model-config is not a JSON object: {err}") from None
    fields = {f.name for f in dataclasses.fields(TrainConfig)}
    cfg = TrainConfig(**{k: v for k, v in vars(args).items() if k in fields})
    train(cfg, args.data, args.out, model_config=model_config, quiet=args.quiet)
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.train"))


if __name__ == "__main__":
    entry_point()
