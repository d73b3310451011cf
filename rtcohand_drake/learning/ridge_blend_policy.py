"""A policy file that blends an exported CCHP policy with a ridge read fitted to the person's own clips.

    python -m rtcohand_drake.learning.ridge_blend_policy --policy CCHP.pt --out FILE.pt
        [--window 10] [--lambda 100] [--folds 4] [--rows 12] [--min-gain G] [--lead L]
        [--switch-below T --switch-ratio R]

Some people are read best by a linear map of their own recent hand motion: their gestures are
steady and their map from gesture to command is unlike anything the CCHP learned from other
people. The file this writes keeps the exported CCHP whole, as a submodule, and adds the ridge
read of `learning.ridge_reference` (the per-person reference) inside the file, fitted when the
context is encoded:

    encode_context:  X = the context steps' last `window` steps of the 36 hand-part velocities
                     (zeros before a clip starts), standardised by their own mean and spread;
                     W = (Xs^T Xs + lambda I)^-1 Xs^T (Y - mean(Y))
    step:            r = xs(t) . W + mean(Y);  mean = B r + (1 - B) mean_CCHP,  read likewise

B is chosen for each person when the context is encoded: the least-squares blend of the two reads
over the person's own clips, each clip read with the clips of the other folds as context (clip b
is in fold b mod F): the CCHP stepped over the clip (its own mean fed back, z the prior mean), the
ridge fitted on the other folds. Over every step of at most `rows` clips spread over the context.
With a context of one clip B is 0 (the CCHP alone). With `--min-gain G` the ridge is used only for a
person whose clips the blend reads with at least G less squared error than the inner file alone,
cross-fitted (`export.blend_and_gain`); for anyone else B = 0 (`blend_choice` gives B, the fitted B
and that share).

With `--switch-below T` the file switches instead of blending: B is 1 (the ridge alone) for a person
whose clips the ridge reads, by the same folds, with less than T of commanding zero twist's squared
error (`ridge_cv`) and less than R times the inner file's error read the same way (`cchp_cv`: the inner
file stepped through at most `rows` clips spread over the context, each with the other folds' clips
as context); else B is 0 (the inner file alone, exactly). `cchp_cv` is stepped only for a person whose
`ridge_cv` is under T (`switch_figures` gives both, -1 where not computed).

The CCHP is fed its own mean, carried in h after its state; then the last `window` - 1 steps of
the input. `std`, the read variance and the attention are the CCHP's.

The inner file may read more than the 36 hand-part velocities (the file for real hands,
`learning.path_shape_policy`, reads the hand's path and shape after them): it is fed every feature,
the ridge the first 36.

Keys (K, D_in + ceil(extra_size / K)): one block whose memory holds the inner file's keys (K, D_in),
then the ridge's mean, spread, W (row-major), mean(Y) and B, so that a step reads each as a view.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import warnings
from typing import List, Optional, Sequence, Tuple

import torch

from rtcohand_drake.data.hand_features import FEATURE_DIM
from rtcohand_drake.errors import InputError, run_cli
from rtcohand_drake.learning.export import WrappedPolicySteps, blend_and_gain
from rtcohand_drake.learning.nets.cchp import lead_labels

# The per-person ridge reference's settings (learning.ridge_reference, the `evaluate --ridge` default);
# the folds and rows as the file for real hands chooses its blend (learning.path_shape_policy).
DEFAULT_WINDOW = 10
DEFAULT_LAMBDA = 100.0
DEFAULT_FOLDS = 4
DEFAULT_ROWS = 12


class RidgeBlendPolicy(WrappedPolicySteps):
    """The exported CCHP policy blended, per person, with a ridge read of their own clips."""

    def __init__(self, inner: torch.jit.ScriptModule, window: int = DEFAULT_WINDOW, lam: float = DEFAULT_LAMBDA,
                 folds: int = DEFAULT_FOLDS, rows: int = DEFAULT_ROWS, min_gain: float = 0.0, lead: int = 0,
                 switch_below: float = 0.0, switch_ratio: float = 1.0):
        super().__init__()
        if int(inner.feature_dim) < FEATURE_DIM or not hasattr(inner, "step_read"):
            raise InputError("the inner policy must read the 36 hand features first and have step_read")
        if not (window >= 1 and lam > 0 and folds >= 0 and rows >= 1 and 0.0 <= min_gain < 1.0 and lead >= 0):
            raise InputError(f"window must be >= 1, lambda positive, folds >= 0, rows >= 1, min_gain in [0, 1) and "
                             f"lead >= 0; got {window}, {lam}, {folds}, {rows}, {min_gain}, {lead}")
        if not (0.0 <= switch_below < 1.0 and switch_ratio > 0.0) or (switch_below > 0.0 and folds < 2):
            raise InputError(f"switch_below must be in [0, 1), switch_ratio positive and folds >= 2 for a switch; "
                             f"got {switch_below}, {switch_ratio}, {folds}")
        self.inner = inner
        self.inner_hidden = int(inner.hidden_size)
        # The inner file reads every feature; the ridge reads the first 36, the hand-part velocities.
        self.feature_dim = int(inner.feature_dim)
        self.motion_feature_dim = FEATURE_DIM
        self.window = int(window)
        self.ridge_dim = self.window * FEATURE_DIM
        self.ridge_lambda = float(lam)
        self.blend_folds = int(folds)
        self.blend_rows = int(rows)
        self.hidden_size = self.inner_hidden + 6 + (self.window - 1) * FEATURE_DIM
        self.latent_dim = int(inner.latent_dim)
        self.query_size = int(inner.query_size)
        self.motion_dim = 6
        self.attention_heads = int(inner.attention_heads) if hasattr(inner, "attention_heads") else 1
        # A person's ridge read is used only if, over their own clips, the fitted blend removes at least
        # this share of the inner read's squared error (else B = 0: the inner file alone).
        self.min_gain = float(min_gain)
        # The ridge is fitted to, and the blend chosen on, each context step's label this many steps on (the
        # clip's last label held past its end): 0, the label as recorded; a CCHP trained to lead the handler's
        # lag reads labels `label_lead` steps on.
        self.label_lead = int(lead)
        # A switch in place of the blend (0: off): the ridge alone for a person whose clips it reads, by folds,
        # under this share of zero twist's error and under `switch_ratio` times the inner file's.
        self.switch_below = float(switch_below)
        self.switch_ratio = float(switch_ratio)
        # Extras: the standardisation's mean and spread, W, mean(Y), B used, B as fitted and its gain, then the
        # switch's ridge_cv and cchp_cv.
        self.extra_size = 2 * self.ridge_dim + 6 * self.ridge_dim + 6 + 3 + 2

    def _columns(self, k: int) -> int:
        return (self.extra_size + k - 1) // k

    def _inner_keys(self, keys: torch.Tensor) -> torch.Tensor:
        """The inner file's keys (K, D_in): the first K x D_in floats of the keys' memory (a view, no copy)."""
        k = keys.size(0)
        d_in = keys.size(1) - self._columns(k)
        return keys.reshape(-1)[:k * d_in].view(k, d_in)

    def _extras(self, keys: torch.Tensor) -> torch.Tensor:
        """The ridge's part of the keys' memory, after the inner file's keys (a view, no copy)."""
        k = keys.size(0)
        start = k * (keys.size(1) - self._columns(k))
        return keys.reshape(-1)[start:start + self.extra_size]

    def _windows(self, x: torch.Tensor) -> torch.Tensor:
        """(T, 36) -> (T, window x 36): each step's last `window` steps, oldest first, zeros before the start."""
        t = x.size(0)
        padded = torch.cat([torch.zeros(self.window - 1, self.motion_feature_dim, dtype=x.dtype), x])
        return torch.cat([padded[j:j + t] for j in range(self.window)], 1)

    def _rows(self, x_c: torch.Tensor, y_c: torch.Tensor, m: torch.Tensor, rows: List[int]
              ) -> Tuple[torch.Tensor, torch.Tensor]:
        xs: List[torch.Tensor] = []
        ys: List[torch.Tensor] = []
        for b in rows:
            n = int(m[b].sum())
            xs.append(self._windows(torch.nan_to_num(x_c[b, :n, :self.motion_feature_dim].to(torch.float64),
                                                     0.0, 0.0, 0.0)))
            y = lead_labels(y_c[b:b + 1], m[b:b + 1], self.label_lead)[0, :n]
            ys.append(torch.nan_to_num(y.to(torch.float64), 0.0, 0.0, 0.0))
        return torch.cat(xs), torch.cat(ys)

    def _stats(self, x: torch.Tensor, y: torch.Tensor) -> List[torch.Tensor]:
        """The sums a ridge is fitted from, for rows x (N, ridge_dim), y (N, 6): [N, sum x, X^T X, X^T Y, sum y];
        the sums of two sets of rows are the sums of their rows together."""
        n = torch.full((1,), float(x.size(0)), dtype=torch.float64)
        return [n, x.sum(0), torch.mm(x.t(), x), torch.mm(x.t(), y), y.sum(0)]

    def _fit_stats(self, stats: List[torch.Tensor]) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(mean, spread, W, mean(Y)) of the ridge on the rows whose sums are `stats` (`_stats`): the rows
        standardised by their own mean and spread, W = (Xs^T Xs + lambda I)^-1 Xs^T (Y - mean(Y))."""
        n = stats[0]
        mean = stats[1] / n
        y_mean = stats[4] / n
        # Xs^T Xs = S^-1 (X^T X - n mean mean^T) S^-1 and Xs^T (Y - mean(Y)) = S^-1 (X^T Y - n mean mean(Y)^T).
        centred = stats[2] - n * torch.outer(mean, mean)
        spread = torch.clamp(torch.sqrt(torch.clamp(torch.diagonal(centred) / n, min=0.0)), min=1e-6)
        a = centred / torch.outer(spread, spread) + self.ridge_lambda * torch.eye(self.ridge_dim, dtype=torch.float64)
        w = torch.linalg.solve(a, (stats[3] - n * torch.outer(mean, y_mean)) / spread.view(-1, 1))
        return mean, spread, w, y_mean

    def _fit(self, x: torch.Tensor, y: torch.Tensor
             ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(mean, spread, W, mean(Y)) of the ridge on rows x (N, ridge_dim), y (N, 6)."""
        return self._fit_stats(self._stats(x, y))

    @torch.jit.export
    def encode_context(self, x_c: torch.Tensor, y_c: torch.Tensor, mask: torch.Tensor
                       ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        if x_c.dim() != 3 or x_c.size(2) != self.feature_dim:
            raise RuntimeError(f"encode_context: x_c must be (B, T, {self.feature_dim}), got {x_c.shape}")
        m = mask.to(torch.bool)
        if y_c.dim() != 3 or y_c.size(2) != 6 or m.shape != x_c.shape[:2] or y_c.shape[:2] != x_c.shape[:2]:
            raise RuntimeError("encode_context: y_c must be (B, T, 6) and mask (B, T), as x_c")
        keys_in, values, z_mu, z_sigma = self.inner.encode_context(x_c, y_c, m)
        n_rows = x_c.size(0)
        blend = torch.zeros(1, dtype=torch.float64)
        fitted = torch.zeros(1, dtype=torch.float64)
        gain = torch.full((1,), -1.0, dtype=torch.float64)  # -1: not cross-validated
        cv = torch.full((2,), -1.0, dtype=torch.float64)  # the switch's ridge_cv and cchp_cv; -1: not computed
        if self.switch_below > 0.0 and n_rows > 1:
            # The folds' sums add up to the whole context's: the ridge read is fitted from them.
            ridge_cv, total = self._ridge_cv(x_c, y_c, m)
            mean, spread, w, y_mean = self._fit_stats(total)
            cv[0] = ridge_cv
            if ridge_cv < self.switch_below:
                cv[1] = self._inner_cv(x_c, y_c, m)
                if ridge_cv < self.switch_ratio * float(cv[1]):
                    blend = torch.ones(1, dtype=torch.float64)
                fitted = blend.clone()
                gain = (1.0 - cv[0] / torch.clamp(cv[1], min=1e-12)).view(1)
        else:
            # A clip's steps are its first mask.sum() steps (the context is packed that way, pack_context).
            mean, spread, w, y_mean = self._fit(*self._rows(x_c, y_c, m, list(range(n_rows))))
            if self.blend_folds > 0 and n_rows > 1:
                fitted_b, gain_b = self._cross_validated_blend(x_c, y_c, m)
                fitted, gain = fitted_b.view(1), gain_b.view(1)
                blend = fitted if float(gain_b) >= self.min_gain else torch.zeros(1, dtype=torch.float64)
        # One (K, D_in + ceil(extras / K)) block whose memory is the inner file's keys, then the ridge's
        # extras: a step reads each as a view, without a copy.
        k = keys_in.size(0)
        d_in = keys_in.size(1)
        flat = torch.zeros(k * (d_in + self._columns(k)), dtype=keys_in.dtype)
        flat[:k * d_in] = keys_in.reshape(-1)
        flat[k * d_in:k * d_in + self.extra_size] = torch.cat([mean, spread, w.reshape(-1), y_mean, blend, fitted,
                                                               gain, cv]).to(keys_in.dtype)
        return flat.view(k, d_in + self._columns(k)), values, z_mu, z_sigma

    def _fold(self, n_rows: int, folds: int, f: int) -> Tuple[List[int], List[int]]:
        """(the clips of fold f, the others): clip b is in fold b mod folds."""
        out_rows: List[int] = []
        in_rows: List[int] = []
        for b in range(n_rows):
            if b % folds == f:
                out_rows.append(b)
            else:
                in_rows.append(b)
        return out_rows, in_rows

    def _ridge_cv(self, x_c: torch.Tensor, y_c: torch.Tensor, m: torch.Tensor) -> Tuple[float, List[torch.Tensor]]:
        """(The ridge's squared error over the person's clips, each read with the ridge fitted on the other
        folds' clips (clip b in fold b mod folds), as a share of zero twist's over the same steps; the whole
        context's sums, `_stats`). Each fold's rows are windowed and summed once; a fit on the other folds
        takes the total less its own."""
        n_rows = x_c.size(0)
        folds = min(self.blend_folds, n_rows)
        held: List[Tuple[torch.Tensor, torch.Tensor]] = []
        sums: List[List[torch.Tensor]] = []
        for f in range(folds):
            x, y = self._rows(x_c, y_c, m, self._fold(n_rows, folds, f)[0])
            held.append((x, y))
            sums.append(self._stats(x, y))
        total: List[torch.Tensor] = []
        for i in range(5):
            part = sums[0][i]
            for f in range(1, folds):
                part = part + sums[f][i]
            total.append(part)
        err = 0.0
        zero = 0.0
        for f in range(folds):
            rest: List[torch.Tensor] = []
            for i in range(5):
                rest.append(total[i] - sums[f][i])
            mean, spread, w, y_mean = self._fit_stats(rest)
            x, y = held[f]
            err += float(((torch.mm((x - mean) / spread, w) + y_mean - y) ** 2).sum())
            zero += float((y * y).sum())
        return (err / zero if zero > 0.0 else float("inf")), total

    def _inner_cv(self, x_c: torch.Tensor, y_c: torch.Tensor, m: torch.Tensor) -> float:
        """The inner file's squared error over at most `rows` of the person's clips spread over the context,
        each stepped from a zero state (its own mean fed back, z the prior mean) with the other folds' clips
        as context, as a share of zero twist's over the same steps."""
        n_rows = x_c.size(0)
        folds = min(self.blend_folds, n_rows)
        picked = torch.unique(torch.round(torch.linspace(0.0, float(n_rows - 1), min(self.blend_rows, n_rows),
                                                         dtype=torch.float64)).to(torch.long))
        picked_rows: List[int] = picked.tolist()
        hi = self.inner_hidden
        err = 0.0
        zero = 0.0
        for f in range(folds):
            in_rows = self._fold(n_rows, folds, f)[1]
            out_rows: List[int] = []
            for b in picked_rows:
                if b % folds == f:
                    out_rows.append(b)
            if len(out_rows) == 0 or len(in_rows) == 0:
                continue
            keep = torch.tensor(in_rows)
            keys, values, z, _ = self.inner.encode_context(x_c[keep], y_c[keep], m[keep])
            for b in out_rows:
                n = int(m[b].sum())
                y = torch.nan_to_num(lead_labels(y_c[b:b + 1], m[b:b + 1], self.label_lead)[0, :n].to(torch.float64),
                                     0.0, 0.0, 0.0)
                h = torch.zeros(hi)
                c = torch.zeros(hi)
                y_prev = torch.zeros(6)
                for t in range(n):
                    y_prev, _, h, c, _, _, _ = self.inner.step_read(
                        torch.nan_to_num(x_c[b, t], 0.0, 0.0, 0.0), y_prev, h, c, keys, values, z)
                    miss = y[t] - y_prev.to(torch.float64)
                    err += float((miss * miss).sum())
                    zero += float((y[t] * y[t]).sum())
        return err / zero if zero > 0.0 else float("inf")

    def _cross_validated_blend(self, x_c: torch.Tensor, y_c: torch.Tensor, m: torch.Tensor
                               ) -> Tuple[torch.Tensor, torch.Tensor]:
        """(B in [0, 1], its cross-fitted gain) (module docstring; `export.blend_and_gain`)."""
        n_rows = x_c.size(0)
        folds = min(self.blend_folds, n_rows)
        stride = max(1, n_rows // self.blend_rows)
        hi = self.inner_hidden
        sums = torch.zeros(n_rows, 3, dtype=torch.float64)  # per clip: gap . miss, |gap|^2, |miss|^2
        for f in range(folds):
            out_rows, in_rows = self._fold(n_rows, folds, f)
            mean, spread, w, y_mean = self._fit(*self._rows(x_c, y_c, m, in_rows))
            keep = torch.tensor(in_rows)
            keys, values, z, _ = self.inner.encode_context(x_c[keep], y_c[keep], m[keep])
            for b in out_rows:
                if b % stride != 0:
                    continue
                x, y = self._rows(x_c, y_c, m, [b])
                ridge = torch.mm((x - mean) / spread, w) + y_mean
                h = torch.zeros(hi)
                c = torch.zeros(hi)
                y_prev = torch.zeros(6)
                for t in range(x.size(0)):
                    y_prev, _, h, c, _, _, _ = self.inner.step_read(
                        torch.nan_to_num(x_c[b, t], 0.0, 0.0, 0.0), y_prev, h, c, keys, values, z)
                    own = y_prev.to(torch.float64)
                    gap = ridge[t] - own
                    miss = y[t] - own
                    sums[b, 0] += (gap * miss).sum()
                    sums[b, 1] += (gap * gap).sum()
                    sums[b, 2] += (miss * miss).sum()
        if sums[:, 1].sum() <= 0:
            return torch.zeros((), dtype=torch.float64), torch.full((), -1.0, dtype=torch.float64)
        return blend_and_gain(sums, stride)

    @torch.jit.export
    def blend_of(self, keys: torch.Tensor) -> torch.Tensor:
        """B, from the keys `encode_context` gave."""
        return self._extras(keys)[8 * self.ridge_dim + 6]

    @torch.jit.export
    def blend_choice(self, keys: torch.Tensor) -> torch.Tensor:
        """[B used, B as fitted, the share of the inner read's squared error over the person's own clips
        that the blend removes, cross-fitted (-1: not cross-validated)] for encoded keys."""
        return self._extras(keys)[8 * self.ridge_dim + 6:8 * self.ridge_dim + 9]

    @torch.jit.export
    def switch_figures(self, keys: torch.Tensor) -> torch.Tensor:
        """[ridge_cv, cchp_cv] of a switch (module docstring) for encoded keys; -1 where not computed."""
        return self._extras(keys)[8 * self.ridge_dim + 9:8 * self.ridge_dim + 11]

    @torch.jit.export
    def attention_of(self, query: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
        """The CCHP's attention over the K context steps."""
        return self.inner.attention_of(query, self._inner_keys(keys))

    def _step(self, x_t: torch.Tensor, h: torch.Tensor, c: torch.Tensor, keys: torch.Tensor,
              values: torch.Tensor, z: torch.Tensor
              ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                         torch.Tensor]:
        if x_t.numel() != self.feature_dim:
            raise RuntimeError(f"step: x_t must have {self.feature_dim} features, got {x_t.numel()}")
        x_t = x_t.view(-1)
        hi = self.inner_hidden
        mean_i, std, h2, c2, read_i, v, query = self.inner.step_read(
            x_t, h[hi:hi + 6], h[:hi], c[:hi], self._inner_keys(keys), values, z)
        extras = self._extras(keys)
        d = self.ridge_dim
        window = torch.cat([h[hi + 6:], torch.nan_to_num(x_t[:self.motion_feature_dim], 0.0, 0.0, 0.0)])
        xs = (window - extras[:d]) / extras[d:2 * d]
        ridge = torch.mv(extras[2 * d:8 * d].view(d, 6).t(), xs) + extras[8 * d:8 * d + 6]
        b = extras[8 * d + 6]
        if float(b) == 0.0:  # the inner file alone, exactly
            mean = mean_i
            read = read_i.mean(0).view(1, 6)
        else:
            mean = b * ridge + (1.0 - b) * mean_i
            read = (b * ridge + (1.0 - b) * read_i.mean(0)).view(1, 6)
        h_next = torch.cat([h2, mean_i, window[self.motion_feature_dim:]])
        c_next = torch.cat([c2, torch.zeros(6 + (self.window - 1) * self.motion_feature_dim)])
        return mean, std, h_next, c_next, read, v, query


def build_ridge_blend_policy(policy: os.PathLike, out: os.PathLike, window: int = DEFAULT_WINDOW,
                             lam: float = DEFAULT_LAMBDA, folds: int = DEFAULT_FOLDS, rows: int = DEFAULT_ROWS,
                             min_gain: float = 0.0, lead: int = 0, switch_below: float = 0.0,
                             switch_ratio: float = 1.0) -> pathlib.Path:
    """Writes the blended policy file, its model card extended with the ridge read's settings."""
    from rtcohand_drake.learning.export import policy_and_card, save_scripted

    inner, card = policy_and_card(policy)
    if "ridge_read" in card:
        raise InputError(f"{policy}: already blends a ridge read; give the CCHP policy it was built from")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.jit")
        scripted = torch.jit.script(RidgeBlendPolicy(inner, window, lam, folds, rows, min_gain, lead, switch_below,
                                                     switch_ratio).eval())
    card = dict(card, ridge_read={
        "inner_policy": pathlib.Path(policy).name, "window": window, "lambda": lam, "blend_folds": folds,
        "blend_rows": rows, "min_gain": min_gain, **({"lead": lead} if lead > 0 else {}),
        **({"switch_below": switch_below, "switch_ratio": switch_ratio} if switch_below > 0 else {}),
        "read": "ridge on the last `window` steps of the 36 hand-part velocities, fitted to the person's clips; " +
                ("the ridge alone for a person whose clips it reads, by folds, under `switch_below` of zero twist's "
                 "error and under `switch_ratio` times the CCHP's; else the CCHP alone" if switch_below > 0 else
                 "blended with the CCHP by B chosen per person by folds of their clips")})
    return save_scripted(scripted, out, card)


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.learning.ridge_blend_policy",
                                description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="an exported 36-feature CCHP policy file")
    p.add_argument("--out", required=True, help="the policy file to write")
    p.add_argument("--window", type=int, default=DEFAULT_WINDOW, help="policy steps the ridge reads (default 10: 1 s)")
    p.add_argument("--lambda", dest="lam", type=float, default=DEFAULT_LAMBDA, help="the ridge's penalty (default 100)")
    p.add_argument("--folds", type=int, default=DEFAULT_FOLDS,
                   help="choose the blend per person by this many folds of their clips (0: the CCHP alone)")
    p.add_argument("--rows", type=int, default=DEFAULT_ROWS, help="clips the choice of the blend steps through, at most")
    p.add_argument("--min-gain", type=float, default=0.0,
                   help="use a person's ridge read only if the fitted blend removes at least this share of the inner "
                        "read's squared error over their own clips (cross-fitted)")
    p.add_argument("--lead", type=int, default=0,
                   help="fit the ridge to, and choose the blend on, each step's label this many steps on (0: the "
                        "label as recorded; the shipped CCHP is trained 2 steps on)")
    p.add_argument("--switch-below", type=float, default=0.0,
                   help="switch instead of blending: the ridge alone for a person whose clips it reads, by the folds, "
                        "under this share of zero twist's squared error and under --switch-ratio times the inner "
                        "file's; else the inner file alone (0: blend)")
    p.add_argument("--switch-ratio", type=float, default=1.0, help="see --switch-below (default 1)")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    out = build_ridge_blend_policy(args.policy, args.out, args.window, args.lam, args.folds, args.rows, args.min_gain,
                                   args.lead, args.switch_below, args.switch_ratio)
    print(f"wrote {out}")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.learning.ridge_blend_policy"))


if __name__ == "__main__":
    entry_point()
