"""Evaluate trained policies on the six test settings of the paper (docs/interfaces.md, the command line).

    python -m rtcohand_drake.evaluate --data PATH.h5 --checkpoint CKPT [CKPT ...] --out DIR
        [--names NAME ...] [--seed 0] [--settings S ...] [--noise-sweep] [--spectrum] [--attention]

`--settings ... Own` adds the deployed setting (out-sample targets, the
user's own other clips as context; `rtcohand_drake.data.sampling`).

Checkpoints that share a name (by default derived from the model kind and its
training options, e.g. "CCHP", "CCHP p_TF=0.9", "RANP", "Dummy LSTM") are
seeds of one model: their metrics are averaged, with the standard deviation
over seeds.

Metrics per setting, averaged over the setting's episodes:
- elbo_loss: -ELBO per target clip (sum over steps and motion dimensions of
  -log N(y; mean, std) in physical units, plus KL(q(z|C,T) || q(z|C))), with
  the previous output fed back from the model's own mean (no teacher forcing)
  and one z drawn from q(z|C,T). For the Dummy LSTM it is the NLL (no latent).
- mse: mean over steps and the 6 motion dimensions of (y - mean)^2, in
  (m/s)^2 and (rad/s)^2, free-running, z = the mean of q(z|C).

Three references get a row in every table: always commanding zero twist, a
ridge regression fitted on exactly each episode's context
(`rtcohand_drake.learning.ridge_reference`, `--ridge WINDOW LAMBDA`), and a
nearest-neighbour read of the recent hand motion fitted alike
(`rtcohand_drake.learning.knn_reference`, `--knn WINDOW K`). On recorded
people (Person) a fourth: a kernel read of the hand's path and shape fitted
alike (`rtcohand_drake.learning.kernel_reference`).

`--checkpoint` also takes exported policy files: a plain CCHP policy
(`models/cchp_core.pt`) is rebuilt as the model it was exported from; a file
that blends in a read fitted to the person (the default, `models/cchp_default.pt`,
`learning.ridge_blend_policy`) or reads the hand's path and shape
(`models/cchp_path_shape.pt`) is stepped as the policy box steps it.
`--settings Person` reads recorded people (`rtcohand_drake.data.import_shrec17`):
each user's held-out clips with their own train clips as context.

Writes DIR/results.json, DIR/results.md, and with the options the figures
noise_sweep.png, spectrum.png, attention.png.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import pathlib
import sys
import zipfile
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from rtcohand_drake.errors import ArgumentParser, InputError, run_cli
from rtcohand_drake.learning.batching import collate
from rtcohand_drake.data.hand_features import FEATURE_DIM
from rtcohand_drake.data.sampling import ALL_SETTINGS, PERSON_SETTING, SETTINGS
from rtcohand_drake.learning.kernel_reference import BANDWIDTH as KERNEL_BANDWIDTH, LAMBDA as KERNEL_LAMBDA
from rtcohand_drake.learning.kernel_reference import KernelReference
from rtcohand_drake.learning.checkpoint import load_model_file, parse_overrides

NOISE_LEVELS = 11  # from (0, 0) to the maxima below, equal increments
MAX_SIGMA_T = 0.05  # m/s
MAX_SIGMA_R = 0.1  # rad/s
HIGH_FREQ_HZ = 1.0  # "high-frequency content": power above this, as a fraction of the total
# The per-person references' settings (window in policy steps): the ridge's as chosen on simulated
# development people; the nearest-neighbour read's as chosen on recorded development people
# (docs/real_people.md). Both are options of the command, to tune them on other data.
RIDGE_DEFAULT = (10, 100.0)
KNN_DEFAULT = (20, 20)

# The paper's Table "Test losses" (its own data): (ELBO loss, MSE); None = NA.
PAPER_TABLE = {
    "Dummy LSTM": [(None, 4.89), None, None, None, (-360.35, 5.48), (None, 5.38)],
    "RANP": [(-410.66, 1.66), (-401.42, 1.95), (-400.76, 1.96), (-400.71, 1.96), (-369.26, 2.54), (-288.59, 4.84)],
    "CCHP": [(-634.45, 1.4), (-566.96, 1.62), (-558.65, 1.62), (-556.71, 1.63), (-346.86, 2.26), (-273.71, 2.28)],
    "CCHP p_TF=0.9": [(9512.59, 8.92), (10554.34, 9.37), (11120.19, 9.37), (11050.91, 9.4), (10000.92, 9.14),
                      (10354.68, 9.15)],
    "CCHP p_TF=0.5": [(-323.25, 1.71), (-172.0, 1.99), (-135.91, 2.01), (-143.76, 2.01), (50.87, 2.64), (721.69, 3.58)],
    "CCHP p_TF=0.1": [(-270.68, 1.96), (-58.68, 2.28), (-51.03, 2.32), (-50.26, 2.32), (248.07, 2.9), (805.37, 3.24)],
    "CCHP (p_D,p_U)=(0.1,0.1)": [(-601.4, 1.43), (-538.96, 1.66), (-537.42, 1.66), (-537.22, 1.66), (-350.8, 2.26),
                                 (-191.37, 2.41)],
    "CCHP (p_D,p_U)=(0.75,0.75)": [(-611.87, 1.36), (-538.34, 1.62), (-498.34, 1.68), (-495.1, 1.7), (-370.33, 2.31),
                                   (-222.07, 2.25)],
    "CCHP (p_D,p_U)=(1,1)": [(-239.82, 1.8), (-13.61, 2.29), (577.09, 2.95), (618.49, 3.04), (465.95, 3.01),
                             (121.30, 2.52)],
}


def model_name(payload: Dict) -> str:
    """A readable name from the checkpoint's kind and training options."""
    kind = payload["kind"]
    tc = payload.get("train_config", {})
    if kind == "lstm":
        return "Dummy LSTM"
    if kind == "ranp":
        return "RANP"
    name = "CCHP"
    sched = tc.get("tf_schedule", "curriculum")
    if sched.startswith("fixed:"):
        name += f" p_TF={float(sched.split(':', 1)[1]):g}"
    p_d, p_u = tc.get("p_d", 0.5), tc.get("p_u", 0.5)
    if (p_d, p_u) != (0.5, 0.5):
        name += f" (p_D,p_U)=({p_d:g},{p_u:g})"
    return name


def episode_batches(episodes: Sequence, chunk: int = 64, features: Optional[List[np.ndarray]] = None):
    """Batches of episodes (targets with their contexts); `features` overrides the target inputs."""
    for i in range(0, len(episodes), chunk):
        part = episodes[i : i + chunk]
        xs = features[i : i + chunk] if features is not None else [e.target_features for e in part]
        yield part, collate([(x, e.target.labels) for x, e in zip(xs, part)], [e.context for e in part])


@torch.no_grad()
def evaluate_episodes(model, episodes: Sequence, seed: int, features: Optional[List[np.ndarray]] = None,
                      keep_means: bool = False) -> Dict:
    """ELBO loss and MSE averaged over episodes (and the predicted means if asked)."""
    g = torch.Generator().manual_seed(seed)
    losses, mses, means = [], [], []
    for part, batch in episode_batches(episodes, features=features):
        terms = model(batch, p_tf=0.0, sample_posterior=True, generator=g)
        losses.append(terms["loss_per_clip"])
        pred = model.predict(batch)
        m = batch.mask.to(pred["mean"].dtype)
        mse = (((batch.y - pred["mean"]) ** 2).mean(-1) * m).sum(1) / m.sum(1).clamp_min(1)
        mses.append(mse)
        if keep_means:
            for j in range(len(part)):
                means.append(pred["mean"][j, : int(batch.mask[j].sum())].numpy())
    if not losses:
        return {"elbo_loss": None, "mse": None, "episodes": 0}
    out = {"elbo_loss": float(torch.cat(losses).mean()), "mse": float(torch.cat(mses).mean()),
           "episodes": int(sum(len(x) for x in mses))}
    if keep_means:
        out["means"] = means
    return out


@torch.no_grad()
def stepped_policy_mse(module, episodes: Sequence) -> Dict:
    """MSE of an exported policy file stepped as the policy box steps it: the context encoded once,
    h, c and the previous mean starting at zero, the module's own mean fed back, z the mean of
    q(z|C). For files that are not rebuilt as a training model (the path-and-shape read,
    `learning.path_shape_policy`); the ELBO needs the training model and is not given."""
    from rtcohand_drake.data.sampling import pack_context

    H = int(module.hidden_size)
    mses = []
    for e in episodes:
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(e.context))
        keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
        h, c, y_prev = torch.zeros(H), torch.zeros(H), torch.zeros(6)
        means = []
        for x in np.nan_to_num(np.asarray(e.target_features, np.float32)):
            y_prev, _, h, c, _ = module.step(torch.from_numpy(x), y_prev, h, c, keys, values, z_mu)
            means.append(y_prev.numpy())
        y = np.asarray(e.target.labels, np.float64)
        mses.append(float(np.mean((y - np.array(means, np.float64)) ** 2)))
    if not mses:
        return {"elbo_loss": None, "mse": None, "episodes": 0}
    return {"elbo_loss": None, "mse": float(np.mean(mses)), "episodes": len(mses)}


def _stepped_policy(path: str):
    """The loaded policy file when it is not a plain CCHP export (it reads the hand's path and shape,
    `feature_dim` > 36, or blends a read fitted to the person, `learning.ridge_blend_policy`): such a
    file is stepped as the policy box steps it. Else None."""
    from rtcohand_drake.learning.policy_file import load_policy, torch_archive_kind

    if pathlib.Path(path).is_file() and zipfile.is_zipfile(path) and torch_archive_kind(path, "policy") == "torchscript":
        module = load_policy(path)
        if int(module.feature_dim) > FEATURE_DIM or hasattr(module, "blend_of"):
            return module
    return None


def zero_twist_mse(episodes: Sequence) -> Optional[float]:
    """MSE of always predicting a zero twist, averaged over episodes like the models' MSE."""
    if not episodes:
        return None
    return float(np.mean([np.mean(np.asarray(e.target.labels, np.float64) ** 2) for e in episodes]))


def reference_mse(episodes: Sequence, make) -> Optional[float]:
    """MSE of a reference fitted on each episode's own context (`make()` gives an unfitted one with
    `fit(pieces)` and `predict(features)`), averaged over episodes like the models' MSE."""
    if not episodes:
        return None
    errors = []
    for e in episodes:
        pred = make().fit(e.context).predict(e.target_features)
        errors.append(float(np.mean((np.asarray(e.target.labels, np.float64) - pred) ** 2)))
    return float(np.mean(errors))


def ridge_reference_mse(episodes: Sequence, window: int = 10, lam: float = 100.0) -> Optional[float]:
    """MSE of a ridge regression fitted on each episode's own context (`RidgeReference`), like the models' MSE."""
    from rtcohand_drake.learning.ridge_reference import RidgeReference

    return reference_mse(episodes, lambda: RidgeReference(window, lam))


def knn_reference_mse(episodes: Sequence, window: int = 20, k: int = 10) -> Optional[float]:
    """MSE of the nearest-neighbour read fitted on each episode's own context (`KnnReference`)."""
    from rtcohand_drake.learning.knn_reference import KnnReference

    return reference_mse(episodes, lambda: KnnReference(window, k))


def _mean_std(values: List[Optional[float]]) -> Tuple[Optional[float], Optional[float]]:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return None, None
    return float(np.mean(vals)), float(np.std(vals)) if len(vals) > 1 else 0.0


def noise_levels() -> List[Tuple[float, float]]:
    """(sigma_T, sigma_R) pairs from (0, 0) to (0.05, 0.1), equal increments."""
    return [(MAX_SIGMA_T * i / (NOISE_LEVELS - 1), MAX_SIGMA_R * i / (NOISE_LEVELS - 1)) for i in range(NOISE_LEVELS)]


def noisy_features(episodes: Sequence, sigma_t: float, sigma_r: float, seed: int) -> List[np.ndarray]:
    from rtcohand_drake.data.sampling import add_feature_noise

    rng = np.random.default_rng([seed, int(round(sigma_t * 1e6)), int(round(sigma_r * 1e6))])
    return [add_feature_noise(e.target.features, sigma_t, sigma_r, rng) for e in episodes]


def power_spectrum(sequences: Sequence[np.ndarray], rate_hz: float, n_fft: int = 64) -> Tuple[np.ndarray, np.ndarray]:
    """Mean power spectrum (over sequences and motion dimensions) of (T, 6) sequences, mean removed."""
    freqs = np.fft.rfftfreq(n_fft, 1.0 / rate_hz)
    acc = np.zeros(len(freqs))
    n = 0
    for s in sequences:
        if len(s) < 4:
            continue
        x = s - s.mean(0, keepdims=True)
        spec = np.abs(np.fft.rfft(x, n=n_fft, axis=0)) ** 2  # zero-padded to n_fft
        acc += spec.mean(1)
        n += 1
    return freqs, acc / max(n, 1)


def high_freq_fraction(freqs: np.ndarray, power: np.ndarray, cutoff: float = HIGH_FREQ_HZ) -> float:
    total = power[1:].sum()
    return float(power[freqs > cutoff].sum() / total) if total > 0 else 0.0


# --------------------------------------------------------------------------- report


def _cell(entry: Dict) -> str:
    if entry.get("mse") is None:
        return "n/a"
    el = entry.get("elbo_loss")
    el_s = "n/a" if el is None else f"{el:.1f} ± {entry.get('elbo_loss_std') or 0:.1f}"
    return f"{el_s} / {entry['mse']:.4g} ± {entry.get('mse_std') or 0:.2g}"


def reference_rows(results: Dict) -> List[Tuple[str, Dict]]:
    """(label, {setting: mse}) of the references a results file holds: zero twist, then the fitted ones."""
    ref = results.get("reference", {})
    rows = [("zero twist", ref.get("zero_twist_mse", {}))]
    if ref.get("ridge_mse"):
        r = ref.get("ridge", {"window": 10, "lam": 100.0})
        rows.append((f"ridge fitted to the context (window {r['window']}, lambda {r['lam']:g})", ref["ridge_mse"]))
    if ref.get("knn_mse"):
        k = ref["knn"]
        rows.append((f"nearest-neighbour read of the context (window {k['window']}, k {k['k']})", ref["knn_mse"]))
    if any(v is not None for v in ref.get("kernel_mse", {}).values()):
        k = ref["kernel"]
        rows.append((f"kernel read of the hand's path and shape (bandwidth {k['bandwidth']:g} x the median "
                     f"distance, lambda {k['lam']:g})", ref["kernel_mse"]))
    return rows


def markdown_report(results: Dict) -> str:
    lines = ["# Evaluation results", "",
             f"Data: `{results['data']}`. Episode seed {results['seed']}. "
             "Cells: ELBO loss (per target clip; NLL for the Dummy LSTM) / MSE (per step and dimension, "
             "(m/s)² and (rad/s)²), mean ± std over training seeds.", ""]
    shown = results.get("settings") or list(SETTINGS)
    header = "| Model | seeds | " + " | ".join(shown) + " |"
    lines += [header, "|" + "---|" * (len(shown) + 2)]
    for name, entry in results["models"].items():
        cells = [_cell(entry["settings"].get(s, {})) for s in shown]
        lines.append(f"| {name} | {entry['seeds']} | " + " | ".join(cells) + " |")
    zero = results.get("reference", {}).get("zero_twist_mse", {})
    if zero:
        lines.append("| zero twist (reference) | - | " + " | ".join(
            "n/a" if zero.get(s) is None else f"n/a / {zero[s]:.4g}" for s in shown) + " |")
    references = reference_rows(results)
    for label, values in references[1:]:
        lines.append(f"| {label} (reference) | - | " + " | ".join(
            "n/a" if values.get(s) is None else f"n/a / {values[s]:.4g}" for s in shown) + " |")
    lines += ["", "Episodes per setting: " + ", ".join(
        f"{s} {results['episodes'].get(s, 0)}" for s in shown), ""]
    if zero:
        lines += ["## MSE as a share of commanding zero twist (lower is better; 1 = no better than zero)", "",
                  "| Model | " + " | ".join(shown) + " |", "|" + "---|" * (len(shown) + 1)]
        rows = [(name, {s: e["settings"].get(s, {}).get("mse") for s in shown})
                for name, e in results["models"].items()] + references[1:]
        for label, values in rows:
            lines.append(f"| {label} | " + " | ".join(
                "n/a" if values.get(s) is None or not zero.get(s) else f"{values[s] / zero[s]:.3f}"
                for s in shown) + " |")
        lines.append("")
    if not any(s in SETTINGS for s in shown):
        return "\n".join(lines) + "\n"
    lines += ["## The paper's values (its real data; compare the ordering, not the numbers)", "",
              "| Model | " + " | ".join(SETTINGS) + " |", "|" + "---|" * (len(SETTINGS) + 1)]
    for name, row in PAPER_TABLE.items():
        cells = []
        for v in row:
            if v is None:
                cells.append("NA")
            else:
                cells.append(f"{'NA' if v[0] is None else v[0]} / {v[1]}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    if results.get("noise_sweep"):
        lines += ["", "## Noise sweep (D+U+, MSE mean over seeds)", "",
                  "| Model | " + " | ".join(f"σT={t:.3f} σR={r:.2f}" for t, r in results["noise_sweep"]["levels"]) + " |",
                  "|" + "---|" * (len(results["noise_sweep"]["levels"]) + 1)]
        for name, d in results["noise_sweep"]["models"].items():
            lines.append(f"| {name} | " + " | ".join(f"{v:.4g}" for v in d["mse"]) + " |")
    if results.get("spectrum"):
        lines += ["", f"## High-frequency content of the predicted means (power above {HIGH_FREQ_HZ:g} Hz / total)", "",
                  "| Model | " + " | ".join(f"σT={lv[0]:.3f} σR={lv[1]:.3f}" for lv in results["spectrum"]["levels"]) + " |",
                  "|" + "---|" * (len(results["spectrum"]["levels"]) + 1)]
        gt = results["spectrum"]["ground_truth_high_freq_fraction"]
        lines.append("| ground truth | " + " | ".join(f"{gt:.4f}" for _ in results["spectrum"]["levels"]) + " |")
        for name, d in results["spectrum"]["models"].items():
            lines.append(f"| {name} | " + " | ".join(f"{v:.4f}" for v in d["high_freq_fraction"]) + " |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- figures


def plot_noise_sweep(sweep: Dict, path: pathlib.Path) -> None:
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone

    x = [r for _, r in sweep["levels"]]
    fig = Figure(figsize=(9, 3.3))
    axes = fig.subplots(1, 2)
    for name, d in sweep["models"].items():
        axes[0].errorbar(x, d["elbo_loss"], yerr=d["elbo_loss_std"], label=name, capsize=2, lw=1)
        axes[1].errorbar(x, d["mse"], yerr=d["mse_std"], label=name, capsize=2, lw=1)
    for ax, title in zip(axes, ("ELBO loss (NLL for Dummy LSTM)", "MSE")):
        ax.set_xlabel("σR (rad/s); σT = σR / 2 (m/s)")
        ax.set_title(title, fontsize=9)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def plot_spectrum(spec: Dict, path: pathlib.Path) -> None:
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone

    levels = spec["levels"]
    fig = Figure(figsize=(3.3 * len(levels), 3.0))
    axes = fig.subplots(1, len(levels), sharey=True)
    for i, lv in enumerate(levels):
        ax = axes[i]
        ax.semilogy(spec["freqs"], spec["ground_truth_power"], "k--", lw=1, label="ground truth")
        for name, d in spec["models"].items():
            ax.semilogy(spec["freqs"], d["power"][i], lw=1, label=name)
        ax.set_title(f"σT={lv[0]:.3f}, σR={lv[1]:.3f}", fontsize=9)
        ax.set_xlabel("frequency (Hz)")
    axes[0].set_ylabel("power of predicted mean")
    axes[-1].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


DIM_NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


def plot_attention(model, episode, path: pathlib.Path) -> None:
    """Target time vs context time attention, with the context velocities alongside."""
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone

    batch = collate([(episode.target_features, episode.target.labels)], [episode.context])
    pred = model.predict(batch, keep_attention=True)
    att = pred["attention"][0]  # (T, heads, K)
    mask = batch.mask_c[0].reshape(-1)
    att = att.mean(1)[:, mask].numpy()  # (T, K valid)
    y_c = batch.y_c[0].reshape(-1, 6)[mask].numpy()
    dims = [int(d) for d in episode.target.active_dims] or list(range(6))
    fig = Figure(figsize=(8, 5.5))
    gs = fig.add_gridspec(2, 2, width_ratios=(1, 4), height_ratios=(4, 1.3), wspace=0.05, hspace=0.08)
    ax_v = fig.add_subplot(gs[0, 0])
    ax_a = fig.add_subplot(gs[0, 1], sharey=ax_v)
    ax_t = fig.add_subplot(gs[1, 1], sharex=ax_a)
    ax_a.imshow(att.T, origin="lower", aspect="auto", cmap="viridis", interpolation="nearest")
    ax_a.set_title(f"attention: target {episode.target.name} (active {', '.join(DIM_NAMES[d] for d in dims)}), "
                   f"context starts with {episode.chosen}", fontsize=8)
    ax_a.tick_params(labelleft=False, labelbottom=False)
    k = np.arange(len(y_c))
    for d in dims:
        ax_v.plot(y_c[:, d], k, lw=1, label=DIM_NAMES[d])
    ax_v.set_ylabel("context step")
    ax_v.set_xlabel("context velocity")
    ax_v.invert_xaxis()
    ax_v.legend(fontsize=6)
    t = np.arange(att.shape[0])
    for d in dims:
        ax_t.plot(t, episode.target.labels[: len(t), d], "k--", lw=1)
        ax_t.plot(t, pred["mean"][0, :, d].numpy(), lw=1, label=f"predicted {DIM_NAMES[d]}")
    ax_t.set_xlabel("target step (dashed: ground truth)")
    ax_t.legend(fontsize=6)
    fig.savefig(path, dpi=90, bbox_inches="tight")


# --------------------------------------------------------------------------- main


def evaluate(data: str, checkpoints: Sequence[str], out: str, names: Optional[Sequence[str]] = None, seed: int = 0,
             settings: Sequence[str] = SETTINGS, sweep: bool = False, spectrum: bool = False,
             attention: bool = False, threads: int = 0, max_episodes: int = 0,
             overrides: Optional[Dict] = None, ridge: Tuple[int, float] = RIDGE_DEFAULT,
             knn: Tuple[int, int] = KNN_DEFAULT) -> Dict:
    from rtcohand_drake.data.sampling import evaluation_episodes
    from rtcohand_drake.learning.train import load_clips

    if threads > 0:
        torch.set_num_threads(threads)
    loaded, stepped = [], {}
    for i, ck in enumerate(checkpoints):
        module = _stepped_policy(ck)
        if module is not None:  # stepped as the policy box steps it (on its wider input, if it reads one)
            from rtcohand_drake.learning.export import read_model_card

            card = read_model_card(ck)
            name = names[i] if names else ("CCHP + path-and-shape read" if int(module.feature_dim) > FEATURE_DIM
                                           else "CCHP + ridge read")
            stepped[ck] = module
            loaded.append((name, ck, None, card))
            continue
        model, payload = load_model_file(ck, overrides)
        name = names[i] if names else model_name(payload)
        loaded.append((name, ck, model, payload))
    rate = loaded[0][3].get("train_config", {}).get("rate_hz", 10.0) if loaded else 10.0
    # The wider input (the hand's path and shape) for the files that read it and for the kernel
    # reference on recorded people; the other models and references read its first 36 columns.
    wide_settings = (list(settings) if any(int(m.feature_dim) > FEATURE_DIM for m in stepped.values())
                     else [s for s in settings if s == PERSON_SETTING])
    wide_clips = load_clips(data, rate, path_shape=bool(wide_settings))
    clips = ([dataclasses.replace(c, features=c.features[:, :FEATURE_DIM]) for c in wide_clips] if wide_settings
             else wide_clips)
    episodes = {s: evaluation_episodes(clips, s, seed) for s in settings}
    if not any(episodes.values()):
        raise InputError(f"{data}: no episodes of {', '.join(settings)} (a file with no users, or no clips for "
                         "these settings)")
    # The same episodes (same clips in the same order, same draws) on the wider input.
    wide = {s: evaluation_episodes(wide_clips, s, seed) for s in wide_settings}
    if max_episodes > 0:
        episodes = {s: e[:max_episodes] for s, e in episodes.items()}
        wide = {s: e[:max_episodes] for s, e in wide.items()}
    per_model: Dict[str, Dict] = {}
    for name, ck, model, payload in loaded:
        entry = per_model.setdefault(name, {"checkpoints": [], "runs": []})
        entry["checkpoints"].append(str(ck))
        if model is None:
            narrow = int(stepped[ck].feature_dim) == FEATURE_DIM
            run = {s: stepped_policy_mse(stepped[ck], episodes[s] if narrow else wide[s]) for s in settings}
        else:
            run = {s: evaluate_episodes(model, episodes[s], seed) for s in settings}
        entry["runs"].append(run)
        entry.setdefault("train", []).append({"step": payload.get("step"), **payload.get("meta", {})})
        print(f"evaluated {name} ({ck}): " + ", ".join(
            f"{s} mse={run[s]['mse']:.4g}" if run[s]["mse"] is not None else f"{s} n/a" for s in settings),
            file=sys.stderr)
    results: Dict = {"data": str(data), "seed": seed, "settings": list(settings), "set": dict(overrides or {}),
                     "episodes": {s: len(episodes[s]) for s in settings}, "models": {},
                     # A policy that always commands zero twist: the floor any useful model must beat.
                     "reference": {"zero_twist_mse": {s: zero_twist_mse(episodes[s]) for s in settings},
                                   # Fitted to each episode's own context: the bar a context read must clear.
                                   "ridge_mse": {s: ridge_reference_mse(episodes[s], *ridge) for s in settings},
                                   "ridge": {"window": ridge[0], "lam": ridge[1]},
                                   # A nonlinear read of the recent hand motion, fitted to each context alike.
                                   "knn_mse": {s: knn_reference_mse(episodes[s], *knn) for s in settings},
                                   "knn": {"window": knn[0], "k": knn[1]},
                                   # The kernel read of the hand's path and shape (recorded people only).
                                   "kernel_mse": {s: reference_mse(wide[s], KernelReference) if s == PERSON_SETTING
                                                  else None for s in settings},
                                   "kernel": {"bandwidth": KERNEL_BANDWIDTH, "lam": KERNEL_LAMBDA}}}
    for name, entry in per_model.items():
        agg = {}
        for s in settings:
            mse_m, mse_s = _mean_std([r[s]["mse"] for r in entry["runs"]])
            el_m, el_s = _mean_std([r[s]["elbo_loss"] for r in entry["runs"]])
            agg[s] = {"mse": mse_m, "mse_std": mse_s, "elbo_loss": el_m, "elbo_loss_std": el_s,
                      "episodes": len(episodes[s]),
                      "per_seed": {"mse": [r[s]["mse"] for r in entry["runs"]],
                                   "elbo_loss": [r[s]["elbo_loss"] for r in entry["runs"]]}}
        results["models"][name] = {"seeds": len(entry["runs"]), "checkpoints": entry["checkpoints"],
                                   "train": entry["train"], "settings": agg}
    out_dir = pathlib.Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    base = evaluation_episodes(clips, "D+U+", seed) if (sweep or spectrum) else []
    if max_episodes > 0:
        base = base[:max_episodes]
    if sweep and base:
        levels = noise_levels()
        sw = {"levels": levels, "setting": "D+U+", "models": {}}
        for name in per_model:
            runs = [m for n, _, m, _ in loaded if n == name and m is not None]
            if not runs:  # a stepped policy file: the sweep needs the training model
                continue
            mse_lv, el_lv, mse_sd, el_sd = [], [], [], []
            for li, (st, sr) in enumerate(levels):
                feats = noisy_features(base, st, sr, seed)
                rs = [evaluate_episodes(m, base, seed, features=feats) for m in runs]
                a, b = _mean_std([r["mse"] for r in rs])
                c, d = _mean_std([r["elbo_loss"] for r in rs])
                mse_lv.append(a), mse_sd.append(b), el_lv.append(c), el_sd.append(d)
            sw["models"][name] = {"mse": mse_lv, "mse_std": mse_sd, "elbo_loss": el_lv, "elbo_loss_std": el_sd}
            print(f"noise sweep {name}: " + " ".join(f"{v:.4g}" for v in mse_lv), file=sys.stderr)
        results["noise_sweep"] = sw
        plot_noise_sweep(sw, out_dir / "noise_sweep.png")
    if spectrum and base:
        levels = [noise_levels()[i] for i in (0, NOISE_LEVELS // 2, NOISE_LEVELS - 1)]
        gt_f, gt_p = power_spectrum([e.target.labels for e in base], rate)
        sp = {"levels": levels, "freqs": gt_f.tolist(), "ground_truth_power": gt_p.tolist(),
              "ground_truth_high_freq_fraction": high_freq_fraction(gt_f, gt_p), "cutoff_hz": HIGH_FREQ_HZ,
              "models": {}}
        for name in per_model:
            model = next(m for n, _, m, _ in loaded if n == name)  # first seed
            if model is None:  # a stepped policy file: the spectrum needs the training model
                continue
            powers, fracs = [], []
            for st, sr in levels:
                feats = noisy_features(base, st, sr, seed)
                r = evaluate_episodes(model, base, seed, features=feats, keep_means=True)
                f, p = power_spectrum(r["means"], rate)
                powers.append(p.tolist())
                fracs.append(high_freq_fraction(f, p))
            sp["models"][name] = {"power": powers, "high_freq_fraction": fracs}
        results["spectrum"] = sp
        plot_spectrum(sp, out_dir / "spectrum.png")
    if attention:
        cchp = next(((n, m) for n, _, m, p in loaded if m is not None and p.get("kind") == "cchp"), None)
        eps = episodes.get("D+U+") or evaluation_episodes(clips, "D+U+", seed)
        if cchp is not None and eps:
            single = [e for e in eps if len(e.target.active_dims) == 1] or list(eps)
            plot_attention(cchp[1], single[0], out_dir / "attention.png")
    (out_dir / "results.json").write_text(json.dumps(results, indent=1))
    (out_dir / "results.md").write_text(markdown_report(results))
    return results


def make_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m rtcohand_drake.evaluate", description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="gesture dataset file (docs/interfaces.md, the gesture dataset file)")
    p.add_argument("--checkpoint", required=True, nargs="+", help="checkpoints; those with the same name are seeds")
    p.add_argument("--names", nargs="+", default=None, help="model names, one per checkpoint")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the evaluation episodes and noise")
    p.add_argument("--settings", nargs="+", choices=ALL_SETTINGS, default=list(SETTINGS),
                   help="the paper's six by default; 'Own' is the deployed setting (the user's own clips as context)")
    p.add_argument("--noise-sweep", action="store_true", help="11 noise levels on D+U+ (noise_sweep.png)")
    p.add_argument("--spectrum", action="store_true", help="spectrum of predictions at three noise levels")
    p.add_argument("--attention", action="store_true", help="attention heatmap of the first CCHP checkpoint")
    p.add_argument("--threads", type=int, default=1, help="torch threads (0: torch default)")
    p.add_argument("--max-episodes", type=int, default=0, help="use at most this many episodes per setting (0: all)")
    p.add_argument("--ridge", nargs=2, type=float, default=list(RIDGE_DEFAULT), metavar=("WINDOW", "LAMBDA"),
                   help=f"the ridge reference's window (policy steps) and lambda (default {RIDGE_DEFAULT[0]} "
                        f"{RIDGE_DEFAULT[1]:g})")
    p.add_argument("--knn", nargs=2, type=int, default=list(KNN_DEFAULT), metavar=("WINDOW", "K"),
                   help=f"the nearest-neighbour reference's window (policy steps) and k (default "
                        f"{KNN_DEFAULT[0]} {KNN_DEFAULT[1]})")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a model option that holds no parameters, for every checkpoint, e.g. "
                        "phi_signed_square_clamp=true (repeatable)")
    return p


def check_reference_args(ridge: Optional[Sequence[float]], knn: Optional[Sequence[int]]) -> None:
    """The per-person references' settings from a command line (`--ridge WINDOW LAMBDA`, `--knn WINDOW K`;
    None: not given), checked before any work: one-line InputErrors."""
    if ridge is not None and not (ridge[0] >= 1 and float(ridge[0]).is_integer() and ridge[1] >= 0):
        raise InputError(f"command line: --ridge WINDOW LAMBDA needs a whole WINDOW >= 1 and LAMBDA >= 0, "
                         f"got {ridge[0]:g} {ridge[1]:g}")
    if knn is not None and not (knn[0] >= 1 and knn[1] >= 1):
        raise InputError(f"command line: --knn WINDOW K needs both >= 1, got {knn[0]} {knn[1]}")


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    if args.names and len(args.names) != len(args.checkpoint):
        raise InputError(f"--names gives {len(args.names)} names for {len(args.checkpoint)} checkpoints")
    check_reference_args(args.ridge, args.knn)
    if pathlib.Path(args.out).exists() and not pathlib.Path(args.out).is_dir():
        raise InputError(f"--out {args.out}: is a file; give a folder")
    results = evaluate(args.data, args.checkpoint, args.out, args.names, args.seed, args.settings,
                       args.noise_sweep, args.spectrum, args.attention, args.threads,
                       args.max_episodes, parse_overrides(args.set), (int(args.ridge[0]), float(args.ridge[1])),
                       (int(args.knn[0]), int(args.knn[1])))
    print(markdown_report(results))
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.evaluate"))


if __name__ == "__main__":
    entry_point()
