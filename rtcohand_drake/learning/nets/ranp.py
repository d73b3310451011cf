"""RANP baseline: an attentive neural process over sliding-window LSTM features
(the paper's baseline 2, after Qin et al. 2019). No output feedback: every
prediction depends on the input window, the context and z only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Optional

import torch
from torch import nn

from rtcohand_drake.learning.batching import Batch
from rtcohand_drake.learning.nets.blocks import FEATURE_DIM, MOTION_DIM, Normalizer, gaussian_kl, mlp
from rtcohand_drake.learning.nets.cchp import (
    CchpConfig,
    ContextAttention,
    ContextEncoding,
    FingerFeatures,
    LatentEncoder,
    OutputHeads,
    likelihood_terms,
)


@dataclass
class RanpConfig(CchpConfig):
    """CCHP's sizes where the blocks match, plus the sliding window."""

    window: int = 10  # steps in each feature window (1 s at 10 Hz)
    # The window LSTM runs once per step and window position; 64 instead of
    # CCHP's 128 keeps a training step as cheap as CCHP's on a 2-core CPU.
    hidden_size: int = 64


class WindowFeatures(nn.Module):
    """Per-frame hand features, then an LSTM over the last `window` frames of each step."""

    def __init__(self, cfg: RanpConfig):
        super().__init__()
        self.fingers = FingerFeatures(cfg)
        self.hand = mlp([self.fingers.out_size] + list(cfg.hand_hidden) + [cfg.hand_feature_size])
        self.lstm = nn.LSTM(cfg.hand_feature_size, cfg.hidden_size, batch_first=True)
        self.window = cfg.window

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x (N, T, 36) normalised -> (N, T, H)."""
        n, t_len, _ = x.shape
        frames = torch.relu(self.hand(self.fingers(x)))  # (N, T, F)
        padded = nn.functional.pad(frames, (0, 0, self.window - 1, 0))
        windows = padded.unfold(1, self.window, 1)  # (N, T, F, W)
        windows = windows.permute(0, 1, 3, 2).reshape(n * t_len, self.window, -1)
        _, (h, _) = self.lstm(windows)
        return h[-1].reshape(n, t_len, -1)


class Ranp(nn.Module):
    kind = "ranp"

    def __init__(self, cfg: Optional[RanpConfig] = None):
        super().__init__()
        self.cfg = cfg or RanpConfig()
        self.normalizer = Normalizer()
        self.features = WindowFeatures(self.cfg)
        self.latent = LatentEncoder(self.cfg)
        self.attention = ContextAttention(self.cfg)
        self.output = OutputHeads(self.cfg)

    def _context(self, batch: Batch, h_c: torch.Tensor):
        b, p, tc, _ = batch.x_c.shape
        y_c = batch.y_c.reshape(b, p * tc, MOTION_DIM) / self.normalizer.label_scale
        mask = batch.mask_c.reshape(b, p * tc)
        h_c = h_c.reshape(b, p * tc, -1)
        feats = self.latent.step_features(h_c, y_c)
        m = mask.unsqueeze(-1).to(feats.dtype)
        sums, counts = (feats * m).sum(1), m.sum(1)
        z_mu, z_sigma = self.latent.from_summary(sums / counts.clamp_min(1.0))
        ctx = ContextEncoding(self.attention.project_keys(h_c), y_c, mask, z_mu, z_sigma)
        return ctx, sums, counts

    def _features(self, batch: Batch, x_t: torch.Tensor):
        b, p, tc, _ = batch.x_c.shape
        scale = self.normalizer.feature_scale
        h_c = self.features(batch.x_c.reshape(b * p, tc, FEATURE_DIM) / scale)
        h_t = self.features(x_t / scale)
        return h_c, h_t

    def _decode(self, h_t: torch.Tensor, ctx: ContextEncoding, z: torch.Tensor, keep_attention: bool = False):
        b, t_len, hid = h_t.shape
        flat = h_t.reshape(b * t_len, hid)
        rep = lambda a: a.unsqueeze(1).expand((b, t_len) + a.shape[1:]).reshape((b * t_len,) + a.shape[1:])
        r, w = self.attention(flat, rep(ctx.keys), rep(ctx.values), rep(ctx.mask))
        mean, std = self.output(r, flat, rep(z))
        attn = w.reshape(b, t_len, w.shape[1], w.shape[2]) if keep_attention else None
        return mean.reshape(b, t_len, MOTION_DIM), std.reshape(b, t_len, MOTION_DIM), attn

    def forward(
        self,
        batch: Batch,
        p_tf: float = 0.0,
        sample_posterior: bool = True,
        generator: Optional[torch.Generator] = None,
        x_noise_std: float = 0.0,
        nll_beta: float = 0.0,
    ) -> Dict[str, torch.Tensor]:
        """Negative ELBO with KL(q(z|C,T) || q(z|C)), as for CCHP. p_tf is unused."""
        x = batch.x
        if x_noise_std > 0.0:
            x = x + x_noise_std * torch.randn(x.shape, generator=generator, device=x.device)
        h_c, h_t = self._features(batch, x)
        ctx, sums, counts = self._context(batch, h_c)
        y_n = batch.y / self.normalizer.label_scale
        feats = self.latent.step_features(h_t, y_n)
        m = batch.mask.unsqueeze(-1).to(feats.dtype)
        post_mu, post_sigma = self.latent.from_summary((sums + (feats * m).sum(1)) / (counts + m.sum(1)).clamp_min(1.0))
        z = post_mu + post_sigma * torch.randn(post_mu.shape, generator=generator) if sample_posterior else post_mu
        mean, std, _ = self._decode(h_t, ctx, z)
        scale = self.normalizer.label_scale
        kl = gaussian_kl(post_mu, post_sigma, ctx.z_mu, ctx.z_sigma)
        return likelihood_terms(batch, mean * scale, std * scale, kl, scale, nll_beta)

    @torch.no_grad()
    def predict(self, batch: Batch, z_from: str = "prior_mean", generator: Optional[torch.Generator] = None,
                keep_attention: bool = False) -> Dict[str, torch.Tensor]:
        h_c, h_t = self._features(batch, batch.x)
        ctx, _, _ = self._context(batch, h_c)
        z = ctx.z_mu if z_from == "prior_mean" else ctx.z_mu + ctx.z_sigma * torch.randn(ctx.z_mu.shape, generator=generator)
        mean, std, attn = self._decode(h_t, ctx, z, keep_attention)
        scale = self.normalizer.label_scale
        out = {"mean": mean * scale, "std": std * scale}
        if attn is not None:
            out["attention"] = attn
        return out
