"""Export a trained CCHP checkpoint as a TorchScript policy (docs/interfaces.md, the exported policy).

    python -m rtcohand_drake.export --checkpoint CKPT --out PATH.pt

`torch.jit.load(PATH)` alone then gives a module with

    encode_context(x_c [B, T, 36], y_c [B, T, 6], mask [B, T] bool)
        -> (keys [K, D], values [K, 6], z_mu [Dz], z_sigma [Dz])
    step(x_t [36], y_prev [6], h [H], c [H], keys [K, D], values [K, 6], z [Dz])
        -> (mean [6], std [6], h [H], c [H], attention [K] (one head) or [heads, K])
    step_with_variance(the same) -> (the same, v [1]): v = 1 + phi^T A phi, the Bayesian
        linear read's predictive variance factor (1 for a softmax-attention read)
    step_read(the same) -> (mean, std, h, c, r [heads, 6], v [1], query [query_size]): the same
        step without the attention; r = attention . values (m/s, rad/s). With the Bayesian
        linear read r = phi^T W, so its cost does not grow with K
    attention_of(query, keys) -> the attention `step` returns for that step

and the integer attributes feature_dim (36), hidden_size (H: the size of the
recurrent state h and c, which includes the gesture cell's state when the
attention keys come from one), latent_dim (Dz), attention_heads, key_size and
query_size.
Inputs and outputs are in physical units (features as the hand-feature module
gives them, twists in m/s and rad/s); NaN features (hand lost) are read as
zeros. K is the number of True entries of `mask`: each context piece (row of
x_c) is encoded from a zero state, and the keys are already projected, so a
step costs one or two LSTM cells and a few small MLPs plus one dot product or
squared distance per context step. The caller keeps (h, c), feeds back the
previous mean as y_prev, starts from zeros, and draws z ~ N(z_mu, z_sigma)
itself (for example on every resume).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import sys
import warnings
from typing import List, Optional, Sequence, Tuple

import torch
from torch import nn

from rtcohand_drake.errors import InputError, run_cli
from rtcohand_drake.learning.nets.blocks import FEATURE_DIM, MOTION_DIM
from rtcohand_drake.learning.nets.cchp import Cchp, blr_prior_precision, clamp_columns, lead_labels
from rtcohand_drake.learning.checkpoint import load_checkpoint, parse_overrides
from rtcohand_drake.learning.policy_file import load_policy  # noqa: F401  (also the export check below)


def pack_blr_keys(phi_a: torch.Tensor, a: torch.Tensor, w: torch.Tensor,
                  bounds: Optional[torch.Tensor] = None) -> torch.Tensor:
    """The Bayesian linear read's keys: one (K, d + ceil((d^2 + 6 d + b) / K)) block whose memory holds
    Phi A (K, d) row-major, then A (d, d), then the read's weights W = A Phi^T Y (d, 6, normalised
    labels), then the b `bounds` if given (the signed-square block's range over the context, lows
    then highs, with `phi_signed_square_clamp`), then zeros. Phi A stays contiguous, so a step that
    returns the attention reads it in one pass over K x d floats; `step_read` needs only A and W."""
    k, d = phi_a.shape
    extra = 0 if bounds is None else bounds.numel()
    tail = d * d + d * 6 + extra  # A, then W (d, 6 motion dimensions), then the bounds
    cols = d + (tail + k - 1) // k
    flat = torch.zeros(k * cols, dtype=phi_a.dtype)
    flat[: k * d] = phi_a.reshape(-1)
    flat[k * d : k * d + d * d] = a.reshape(-1)
    flat[k * d + d * d : k * d + d * d + d * 6] = w.reshape(-1)
    if bounds is not None:
        flat[k * d + d * d + d * 6 : k * d + tail] = bounds.reshape(-1)
    return flat.view(k, cols)


def unpack_blr_bounds(keys: torch.Tensor, d: int, n: int) -> Tuple[torch.Tensor, torch.Tensor]:
    """(lows (1, n), highs (1, n)): the bounds `pack_blr_keys` wrote after W (views, no copy)."""
    k = keys.size(0)
    start = k * d + d * d + d * 6
    flat = keys.reshape(-1)
    return flat[start : start + n].view(1, n), flat[start + n : start + 2 * n].view(1, n)


def unpack_blr_keys(keys: torch.Tensor, d: int) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(Phi A (K, d), A (d, d), W (d, 6)) from the keys `pack_blr_keys` wrote (views, no copy)."""
    k = keys.size(0)
    m = 6  # MOTION_DIM (a literal: TorchScript does not close over globals)
    flat = keys.reshape(-1)
    start = k * d + d * d
    return flat[: k * d].view(k, d), flat[k * d : start].view(d, d), flat[start : start + d * m].view(d, m)


def blend_and_gain(sums: torch.Tensor, stride: int) -> Tuple[torch.Tensor, torch.Tensor]:
    """The blend of a second read with a base read, fitted per person, and what it gains.

    `sums` (clips, 3): for each clip of the person's context, over its steps, (gap . miss, |gap|^2,
    |miss|^2), gap = the second read - the base read and miss = the label - the base read, each clip
    read with the other folds' clips as context; rows other than every `stride`-th are zero (not
    stepped). Returns (the least-squares blend in [0, 1] over every stepped clip, the gain): the share
    of the base read's squared error over those clips that the blend removes, cross-fitted so that it
    is not flattered by the blend's own fit: the stepped clips are taken alternately into two halves,
    and each half is read with the blend fitted on the other. The caller checks |gap|^2 > 0."""
    total = sums.sum(0)
    fitted = torch.clamp(total[0] / total[1], 0.0, 1.0)
    stepped = torch.arange(0, sums.size(0), stride)
    halves = [sums[stepped[0::2]].sum(0), sums[stepped[1::2]].sum(0)]
    removed = torch.zeros((), dtype=sums.dtype)
    for i in range(2):
        other = halves[1 - i]
        blend = torch.clamp(other[0] / other[1], 0.0, 1.0) if float(other[1]) > 0 else torch.zeros((), dtype=sums.dtype)
        removed += 2.0 * blend * halves[i][0] - blend * blend * halves[i][1]
    return fitted, removed / torch.clamp(total[2], min=1e-12)


class WrappedPolicySteps(nn.Module):
    """The exported steps of a policy file that wraps an exported CCHP policy and adds a read of its own
    (`learning.path_shape_policy`, `learning.ridge_blend_policy`): the subclass defines `_step(x_t, h, c,
    keys, values, z) -> (mean, std, h, c, read [1, 6], v [1], query)` and `attention_of(query, keys)`;
    `y_prev` is not used (such a file carries the CCHP's own mean in h)."""

    @torch.jit.export
    def step_read(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
                  keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor
                  ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                             torch.Tensor, torch.Tensor]:
        """(mean, std, h, c, read [1, 6], v [1], query [query_size]); `y_prev` is not used (the
        CCHP's own mean is carried in h)."""
        return self._step(x_t, h, c, keys, values, z)

    @torch.jit.export
    def step_with_variance(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
                           keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor
                           ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                                      torch.Tensor]:
        mean, std, h2, c2, _, v, query = self._step(x_t, h, c, keys, values, z)
        return mean, std, h2, c2, self.attention_of(query, keys), v

    @torch.jit.export
    def step(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
             keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor
             ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        mean, std, h2, c2, _, v, query = self._step(x_t, h, c, keys, values, z)
        return mean, std, h2, c2, self.attention_of(query, keys)


class CchpPolicy(nn.Module):
    """The deployable CCHP: context encoding once, then one cheap step per frame."""

    def __init__(self, model: Cchp):
        super().__init__()
        cfg = model.cfg
        self.feature_dim = FEATURE_DIM
        self.motion_dim = MOTION_DIM
        # h and c carry the gesture cell's state too, when there is one, and with a windowed Bayesian
        # linear read, h also the last (phi_window - 1) normalised frames (c zeros there).
        self.state_size = cfg.state_size
        self.phi_window = int(cfg.phi_window) if model.blr is not None else 0
        self.buffer_size = max(0, self.phi_window - 1) * FEATURE_DIM
        self.hidden_size = cfg.state_size + self.buffer_size
        self.cell_size = cfg.hidden_size
        self.key_offset = model.attention.key_offset
        self.latent_dim = cfg.latent_dim
        self.attention_heads = cfg.attention_heads
        self.key_size = cfg.key_size
        self.std_min = float(cfg.std_min)
        self.read_skip = bool(cfg.read_skip)
        self.latent_std_min = float(cfg.latent_std_min)
        self.distance_kernel = cfg.attention_kernel == "distance"
        self.key_scale = 1.0 if self.distance_kernel else 1.0 / math.sqrt(cfg.key_size)
        self.register_buffer("feature_scale", model.normalizer.feature_scale.detach().clone())
        self.register_buffer("label_scale", model.normalizer.label_scale.detach().clone())
        self.fingers = model.cell.fingers.net
        self.hand = model.cell.hand
        self.lstm = model.cell.lstm
        self.has_gesture_cell = model.cell.gesture is not None
        # A 1-unit placeholder when there is no gesture cell, so the scripted module has one type; never run.
        self.gesture = model.cell.gesture if model.cell.gesture is not None else nn.LSTMCell(1, 1)
        self.aggregate = model.latent.aggregate
        self.trunk = model.latent.trunk
        self.mu_head = model.latent.mu_head
        self.sigma_head = model.latent.sigma_head
        # The softmax read's key/query projection; a 1-unit placeholder with the Bayesian linear read
        # (which never runs it), set below.
        self.kq = model.attention.kq
        # The Bayesian linear read (CchpConfig.read "bayes_linear"): keys hold Phi A (K, d) and the
        # posterior covariance A (d, d) (`pack_blr_keys`), so a step reads r = a . values with
        # a = (Phi A) phi (one contiguous pass over K x d) and v = 1 + phi^T A phi in O(d^2).
        # A 1-unit placeholder projection otherwise; never run.
        self.bayes_linear = model.blr is not None
        if self.bayes_linear:
            self.kq = nn.Linear(1, 1)
        self.phi_proj = model.blr.proj if model.blr is not None else nn.Linear(1, 1)
        self.has_window_proj = model.blr is not None and model.blr.window_proj is not None
        self.window_proj = model.blr.window_proj if self.has_window_proj else nn.Linear(1, 1)
        self.phi_raw = bool(model.blr.raw) if model.blr is not None else False
        self.phi_signed_square = bool(model.blr.signed_square) if model.blr is not None else False
        self.phi_dim = int(model.blr.dim) if model.blr is not None else 0
        self.blr_lambda = float(model.blr.lam.detach()) if model.blr is not None else 1.0
        self.ssq_start = int(model.blr.ssq_start) if model.blr is not None else 0
        self.ssq_stop = int(model.blr.ssq_stop) if model.blr is not None else 0
        self.ssq_prior_weight = float(model.blr.ssq_prior_weight) if model.blr is not None else 0.0
        # With phi_signed_square_clamp, a step's signed-square block is clamped to the context's range,
        # which encode_context packs into the keys after W (`pack_blr_keys`).
        self.ssq_clamp = bool(model.blr.clamp) if model.blr is not None else False
        # The read is solved for each context step's label this many steps later (CchpConfig.label_lead).
        self.label_lead = int(cfg.label_lead)
        if model.blr is not None:
            self.key_size = self.phi_dim  # Phi A's width; D = d + ceil((d^2 + 6 d [+ 72 with the clamp]) / K) in all (pack_blr_keys)
        # The size of `step_read`'s query, from which `attention_of` gives the attention: phi (d) for the
        # Bayesian linear read, the attention query (heads * key_size) otherwise.
        self.query_size = self.phi_dim if self.bayes_linear else cfg.attention_heads * cfg.key_size
        # Per-dimension output MLPs as (6, in, out) weights and (6, 1, out) biases for bmm. With one
        # read (one head), every dimension's first layer sees the same input [r, h, z], so that layer
        # is one (in, 6 * out) matrix (dimension-major columns) for a single product instead. The
        # form not used is an empty placeholder, so the scripted module has one type.
        weights = [w.detach() for w in model.output.net.weights]
        biases = [b.detach() for b in model.output.net.biases]
        one_read = cfg.attention_heads == 1 or model.blr is not None
        self.out_first_size = int(weights[0].size(2))
        if one_read:
            self.out_first_weight = weights[0].permute(1, 0, 2).reshape(weights[0].size(1), -1).contiguous()
            self.out_first_bias = biases[0].reshape(1, -1).clone()
            self.out_first_weights, self.out_first_biases = torch.zeros(0, 0, 0), torch.zeros(0, 0, 0)
        else:
            self.out_first_weight, self.out_first_bias = torch.zeros(0, 0), torch.zeros(0, 0)
            self.out_first_weights = weights[0].clone()
            self.out_first_biases = biases[0].clone().unsqueeze(1)
        self.out_weights: List[torch.Tensor] = [w.clone() for w in weights[1:]]
        self.out_biases: List[torch.Tensor] = [b.clone().unsqueeze(1) for b in biases[1:]]

    def _cell(self, finger_feat: torch.Tensor, y_prev_n: torch.Tensor, h: torch.Tensor, c: torch.Tensor
              ) -> Tuple[torch.Tensor, torch.Tensor]:
        n = self.cell_size
        h_main = h[:, :n]
        hand_feat = torch.relu(self.hand(torch.cat([finger_feat, h_main], 1)))
        h2, c2 = self.lstm(torch.cat([hand_feat, y_prev_n], 1), (h_main, c[:, :n]))
        if self.has_gesture_cell:
            g, cg = self.gesture(finger_feat, (h[:, n:self.state_size], c[:, n:self.state_size]))
            h2 = torch.cat([h2, g], 1)
            c2 = torch.cat([c2, cg], 1)
        return h2, c2

    def _phi(self, g: torch.Tensor, x_n: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
        parts = [self.phi_proj(g)]
        if self.phi_raw:
            parts.append(x_n)
        if self.has_window_proj:
            parts.append(self.window_proj(window))
        if self.phi_signed_square:
            frames = window.view(window.size(0), -1, self.feature_dim)
            parts.append((frames * frames.abs()).sum(1))
        parts.append(torch.ones(g.size(0), 1))
        return torch.cat(parts, 1)

    @torch.jit.export
    def encode_context(self, x_c: torch.Tensor, y_c: torch.Tensor, mask: torch.Tensor
                       ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        if x_c.dim() != 3 or x_c.size(2) != self.feature_dim:
            raise RuntimeError("encode_context: x_c must be [B, T, 36]")
        if y_c.dim() != 3 or y_c.size(2) != self.motion_dim or y_c.size(0) != x_c.size(0) or y_c.size(1) != x_c.size(1):
            raise RuntimeError("encode_context: y_c must be [B, T, 6] like x_c")
        if mask.dim() != 2 or mask.size(0) != x_c.size(0) or mask.size(1) != x_c.size(1):
            raise RuntimeError("encode_context: mask must be [B, T] like x_c")
        mask = mask.to(torch.bool)
        if not bool(mask.any()):
            raise RuntimeError("encode_context: the mask selects no context step")
        b = x_c.size(0)
        t_len = x_c.size(1)
        x = torch.nan_to_num(x_c.to(torch.float32), 0.0, 0.0, 0.0) / self.feature_scale
        y = y_c.to(torch.float32) / self.label_scale
        fingers = self.fingers(x.reshape(b, t_len, 6, 6)).reshape(b, t_len, -1)
        h = torch.zeros(b, self.state_size)
        c = torch.zeros(b, self.state_size)
        y_prev = torch.zeros(b, self.motion_dim)
        hs: List[torch.Tensor] = []
        for t in range(t_len):
            h, c = self._cell(fingers[:, t], y_prev, h, c)
            hs.append(h)
            y_prev = y[:, t]
        h_all = torch.stack(hs, 1)[mask]  # (K, H)
        y_valid = y[mask]  # (K, 6), normalised
        # What the read is solved for: each step's label label_lead steps later (K, 6), m/s and rad/s.
        values = lead_labels(y_c.to(torch.float32), mask, self.label_lead)[mask]
        if self.bayes_linear:
            if self.has_window_proj:
                padded = nn.functional.pad(x, [0, 0, self.phi_window - 1, 0])
                win = torch.cat([padded[:, k : k + t_len] for k in range(self.phi_window)], 2)[mask]
            else:
                win = torch.zeros(1, 1)
            phi = self._phi(h_all[:, self.cell_size:self.state_size], x[mask], win)  # (K, d)
            prior = blr_prior_precision(phi, torch.ones(phi.size(0), 1), torch.tensor(self.blr_lambda),
                                        self.ssq_start, self.ssq_stop, self.ssq_prior_weight)
            gram = torch.mm(phi.t(), phi) + torch.diag(prior)
            A = torch.cholesky_inverse(torch.linalg.cholesky(gram))
            phi_a = torch.mm(phi, A)
            w = torch.mm(phi_a.t(), values / self.label_scale)
            if self.ssq_clamp:
                block = phi[:, self.ssq_start:self.ssq_stop]
                keys = pack_blr_keys(phi_a, A, w, torch.cat([block.min(0)[0], block.max(0)[0]]))
            else:
                keys = pack_blr_keys(phi_a, A, w)  # (K, d + ceil((d^2 + 6 d) / K))
        else:
            keys = self.kq(h_all[:, self.key_offset:]) * self.key_scale  # (K, heads * key_size)
        s = self.aggregate(torch.cat([h_all, y_valid], 1)).mean(0, keepdim=True)
        g = self.trunk(s)
        z_mu = self.mu_head(g)[0]
        z_sigma = self.latent_std_min + (1.0 - self.latent_std_min) * torch.sigmoid(self.sigma_head(g)[0])
        return keys, values, z_mu, z_sigma

    def _softmax_weights(self, q: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
        """Softmax attention weights (heads, K) of the query q (1, heads * key_size) over the context keys."""
        if self.distance_kernel:
            k = keys.size(0)
            diff = keys.view(k, self.attention_heads, self.key_size) - q.view(1, self.attention_heads, self.key_size)
            scores = -(diff * diff).sum(2).t()  # (heads, K)
        elif self.attention_heads == 1:
            scores = torch.mm(q, keys.t())  # (1, K)
        else:
            k = keys.size(0)
            scores = (keys.view(k, self.attention_heads, self.key_size)
                      * q.view(1, self.attention_heads, self.key_size)).sum(2).t()  # (heads, K)
        return torch.softmax(scores, 1)

    def _weights(self, query: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
        """The attention (heads, K) of a step's query: the Bayesian linear read's equivalent kernel
        phi^T A Phi^T (signed), or the softmax attention."""
        if self.bayes_linear:
            phi_a, _, _ = unpack_blr_keys(keys, self.phi_dim)
            return torch.mm(query, phi_a.t())
        return self._softmax_weights(query, keys)

    @torch.jit.export
    def attention_of(self, query: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
        """The attention [K] (one head) or [heads, K] of a `step_read` query over the context: what
        `step` returns as its attention for the same step."""
        weights = self._weights(query.view(1, -1), keys)
        return weights[0] if self.attention_heads == 1 else weights

    @torch.jit.export
    def step(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
             keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor
             ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        mean, std, h2, c2, attention, _ = self.step_with_variance(x_t, y_prev, h, c, keys, values, z)
        return mean, std, h2, c2, attention

    @torch.jit.export
    def step_with_variance(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
                           keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor
                           ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                                      torch.Tensor]:
        """`step`, plus the read's predictive variance factor v = 1 + phi^T A phi ([1]; 1 without the
        Bayesian linear read): how unlike every context gesture this one is."""
        mean, std, h2, c2, _, v, _, weights = self._step(x_t, y_prev, h, c, keys, values, z, True)
        attention = weights[0] if self.attention_heads == 1 else weights
        return mean, std, h2, c2, attention, v

    @torch.jit.export
    def step_read(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
                  keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor
                  ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                             torch.Tensor, torch.Tensor]:
        """`step_with_variance` without the attention: (mean, std, h, c, r [heads, 6], v [1],
        query [query_size]). r is the context read in m/s and rad/s (attention . values), and
        `attention_of(query, keys)` gives the attention when it is wanted. With the Bayesian linear
        read, r = phi^T W from the encoded context, so the step costs O(d^2) whatever the number
        of context steps (it does not read `values`)."""
        mean, std, h2, c2, r, v, query, _ = self._step(x_t, y_prev, h, c, keys, values, z, False)
        return mean, std, h2, c2, r * self.label_scale, v, query.view(-1)

    def _step(self, x_t: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor,
              keys: torch.Tensor, values: torch.Tensor, z: torch.Tensor, with_attention: bool
              ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                         torch.Tensor, torch.Tensor]:
        """(mean, std, h, c, r normalised (heads, 6), v, query (1, query_size), attention (heads, K),
        empty (heads, 0) for a Bayesian linear read without `with_attention`)."""
        x = torch.nan_to_num(x_t, 0.0, 0.0, 0.0) / self.feature_scale
        finger_feat = self.fingers(x.view(6, 6)).view(1, -1)
        h_in = h.view(1, -1)
        h2, c2 = self._cell(finger_feat, (y_prev / self.label_scale).view(1, -1), h_in[:, :self.state_size],
                            c.view(1, -1)[:, :self.state_size])
        variance_factor = torch.ones(1)
        window = torch.zeros(1, 1)
        if self.has_window_proj:
            window = torch.cat([h_in[:, self.state_size:], x.view(1, -1)], 1)  # the last frames, oldest first
        if self.bayes_linear:
            query = self._phi(h2[:, self.cell_size:self.state_size], x.view(1, -1), window)  # phi (1, d)
            if self.ssq_clamp:
                lo, hi = unpack_blr_bounds(keys, self.phi_dim, self.ssq_stop - self.ssq_start)
                query = clamp_columns(query, lo, hi, self.ssq_start, self.ssq_stop)
            _, A, read_w = unpack_blr_keys(keys, self.phi_dim)
            variance_factor = 1.0 + torch.clamp((torch.mm(query, A) * query).sum(), min=0.0).view(1)
            if with_attention:
                weights = self._weights(query, keys)  # (1, K): the equivalent kernel, signed
                r = torch.mm(weights, values) / self.label_scale
            else:
                weights = torch.zeros(1, 0)
                r = torch.mm(query, read_w)  # the same read, without the pass over the K steps
        else:
            query = self.kq(h2[:, self.key_offset:])  # (1, heads * key_size)
            weights = self._softmax_weights(query, keys)
            r = torch.mm(weights, values) / self.label_scale  # (heads, 6)

        if r.size(0) == 1:
            inp = torch.addmm(self.out_first_bias, torch.cat([r, h2, z.view(1, -1)], 1), self.out_first_weight)
            inp = inp.view(6, 1, self.out_first_size)
        else:  # head d's read goes to dimension d
            hz = torch.cat([h2, z.view(1, -1)], 1)
            inp = torch.cat([r.expand(6, 6), hz.expand(6, hz.size(1))], 1).unsqueeze(1)  # (6, 1, in)
            inp = torch.baddbmm(self.out_first_biases, inp, self.out_first_weights)
        n_layers = len(self.out_weights)
        if n_layers > 0:
            inp = torch.relu(inp)
        i = 0
        for w, bias in zip(self.out_weights, self.out_biases):
            inp = torch.baddbmm(bias, inp, w)
            if i < n_layers - 1:
                inp = torch.relu(inp)
            i += 1
        out = inp.view(6, 2)
        scale = self.label_scale
        mean_n = out[:, 0]
        if self.read_skip:  # dimension d adds its read of dimension d
            mean_n = mean_n + torch.diagonal(r.expand(6, 6))
        mean = mean_n * scale
        std = (self.std_min + (1.0 - self.std_min) * nn.functional.softplus(out[:, 1])) * scale
        std = std * torch.sqrt(variance_factor)
        if self.buffer_size > 0:  # carry the newest (phi_window - 1) frames to the next step
            h2 = torch.cat([h2, window[:, self.feature_dim:]], 1)
            c2 = torch.cat([c2, torch.zeros(1, self.buffer_size)], 1)
        return mean, std, h2.view(-1), c2.view(-1), r, variance_factor, query, weights


def script_policy(model: Cchp) -> torch.jit.ScriptModule:
    if not isinstance(model, Cchp):
        raise InputError(f"only CCHP checkpoints can be exported, got a {getattr(model, 'kind', type(model).__name__)} model")
    model = model.eval()
    policy = CchpPolicy(model).eval()
    for param in policy.parameters():
        param.requires_grad_(False)  # no autograd bookkeeping in the deployed step
    return torch.jit.script(policy)


def export_checkpoint(checkpoint: os.PathLike, out: os.PathLike) -> pathlib.Path:
    """Script the checkpoint's model and write it to `out` (with a JSON model card as an extra file)."""
    model, payload = load_checkpoint(checkpoint)
    if payload["kind"] != "cchp":
        raise InputError(f"{checkpoint}: only CCHP checkpoints can be exported, this one holds {payload['kind']!r}")
    card = {
        "kind": payload["kind"],
        "model_config": payload["model_config"],
        "train_config": payload.get("train_config", {}),
        "step": payload.get("step"),
        "meta": payload.get("meta", {}),
    }
    return export_model(model, card, out)


def policy_and_card(path: os.PathLike) -> Tuple[torch.jit.ScriptModule, dict]:
    """An exported policy and the JSON model card it carries (`export_checkpoint`)."""
    extra = {"model_card.json": ""}
    load_policy(path)  # a clear error for a missing or wrong file first
    module = torch.jit.load(str(path), map_location="cpu", _extra_files=extra)
    if not extra["model_card.json"]:
        raise InputError(f"{path}: the policy file has no model card")
    return module, json.loads(extra["model_card.json"])


def read_model_card(path: os.PathLike) -> dict:
    """The JSON model card an exported policy carries."""
    return policy_and_card(path)[1]


def cchp_from_policy(path: os.PathLike, overrides: Optional[dict] = None) -> Tuple[Cchp, dict]:
    """The CCHP model (eval mode) an exported policy file was made from, and its model card.

    `overrides` changes model options that hold no parameters (how the context is read, for
    example `phi_signed_square_prior`); an option that changes a weight's shape is an InputError.
    The rebuilt model exports to a policy that computes what the file computes (tested)."""
    from rtcohand_drake.learning.checkpoint import build_model

    module, card = policy_and_card(path)
    if card.get("kind") != "cchp":
        raise InputError(f"{path}: only CCHP policies can be rebuilt, this one is {card.get('kind')!r}")
    config = {**card["model_config"], **(overrides or {})}
    try:
        model = build_model("cchp", config)
    except (TypeError, ValueError) as err:
        raise InputError(f"{path}: cannot rebuild with {overrides}: {err}") from None
    state = module.state_dict()
    pairs = [("fingers", model.cell.fingers.net), ("hand", model.cell.hand), ("lstm", model.cell.lstm),
             ("aggregate", model.latent.aggregate), ("trunk", model.latent.trunk), ("mu_head", model.latent.mu_head),
             ("sigma_head", model.latent.sigma_head)]
    if model.cell.gesture is not None:
        pairs.append(("gesture", model.cell.gesture))
    if model.blr is not None:
        pairs.append(("phi_proj", model.blr.proj))
        if model.blr.window_proj is not None:
            pairs.append(("window_proj", model.blr.window_proj))
    else:
        pairs.append(("kq", model.attention.kq))
    try:
        for prefix, target in pairs:
            target.load_state_dict({k[len(prefix) + 1:]: v for k, v in state.items() if k.startswith(prefix + ".")})
        model.normalizer.set_scales(state["feature_scale"], state["label_scale"])
        out = model.output.net
        with torch.no_grad():
            if int(module.attention_heads) == 1 or model.blr is not None:  # undo CchpPolicy's one-matrix first layer
                first = module.out_first_weight
                out.weights[0].copy_(first.reshape(first.size(0), MOTION_DIM, -1).permute(1, 0, 2))
                out.biases[0].copy_(module.out_first_bias.reshape(MOTION_DIM, -1))
            else:
                out.weights[0].copy_(module.out_first_weights)
                out.biases[0].copy_(module.out_first_biases.squeeze(1))
            for i, (w, b) in enumerate(zip(module.out_weights, module.out_biases)):
                out.weights[i + 1].copy_(w)
                out.biases[i + 1].copy_(b.squeeze(1))
            if model.blr is not None:
                model.blr.log_lambda.fill_(math.log(float(module.blr_lambda)))
    except (RuntimeError, KeyError) as err:
        raise InputError(f"{path}: the options {overrides} do not fit the file's weights "
                         f"({str(err).splitlines()[0][:160]})") from None
    return model.eval(), card


def save_scripted(scripted: torch.jit.ScriptModule, out: os.PathLike, card: dict,
                  card_name: str = "model_card.json") -> pathlib.Path:
    """Write a scripted module to `out` with `card` as the JSON file `card_name` inside it, atomically
    (a write that fails leaves any earlier file whole)."""
    out = pathlib.Path(out)
    if out.is_dir():
        raise InputError(f"--out {out}: is a folder; give a file path")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    try:
        torch.jit.save(scripted, str(tmp), _extra_files={card_name: json.dumps(card, indent=1)})
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return out


def export_model(model: Cchp, card: dict, out: os.PathLike) -> pathlib.Path:
    """Script `model` and write it to `out` with `card` as its model card (atomically)."""
    return save_scripted(script_policy(model), out, card)


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.export", description="Export a CCHP checkpoint as TorchScript.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="checkpoint written by python -m rtcohand_drake.train")
    src.add_argument("--from-policy", help="an exported policy file, re-exported with --set options changed")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="with --from-policy: a model option that holds no parameters, e.g. "
                        "phi_signed_square_prior=context (repeatable)")
    p.add_argument("--out", required=True, help="TorchScript file to write (.pt)")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = make_parser()
    args = p.parse_args(argv)
    # TorchScript is the deployment format of docs/interfaces.md (the exported policy); its deprecation notice is noise here.
    warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.jit")
    if args.checkpoint:
        if args.set:
            p.error("--set goes with --from-policy")
        out = export_checkpoint(args.checkpoint, args.out)
    else:
        overrides = parse_overrides(args.set)
        model, card = cchp_from_policy(args.from_policy, overrides)
        card = {**card, "model_config": model.cfg.to_dict(),
                "meta": {**card.get("meta", {}), "derived_from": {"policy": pathlib.Path(args.from_policy).name,
                                                                   "set": overrides}}}
        out = export_model(model, card, args.out)
    load_policy(out)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB)")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.export"))


if __name__ == "__main__":
    entry_point()
