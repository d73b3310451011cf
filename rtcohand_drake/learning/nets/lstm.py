"""Dummy LSTM baseline: MLP hand features and a two-layer LSTM, no context,
trained on the negative log-likelihood (the paper's baseline 1)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional

import torch
from torch import nn

from rtcohand_drake.learning.batching import Batch
from rtcohand_drake.learning.nets.blocks import MOTION_DIM, Normalizer, PerDimensionMLP, bounded_std, mlp
from rtcohand_drake.learning.nets.cchp import FingerFeatures, likelihood_terms


@dataclass
class LstmConfig:
    hidden_size: int = 128
    num_layers: int = 2
    finger_sizes: List[int] = field(default_factory=lambda: [6, 32, 32])
    hand_hidden: List[int] = field(default_factory=lambda: [128, 64])
    hand_feature_size: int = 32
    output_hidden: List[int] = field(default_factory=lambda: [128, 64])
    std_min: float = 0.1

    def to_dict(self) -> Dict:
        return asdict(self)


class DummyLstm(nn.Module):
    kind = "lstm"

    def __init__(self, cfg: Optional[LstmConfig] = None):
        super().__init__()
        self.cfg = cfg or LstmConfig()
        self.normalizer = Normalizer()
        self.fingers = FingerFeatures(self.cfg)
        self.hand = mlp([self.fingers.out_size] + list(self.cfg.hand_hidden) + [self.cfg.hand_feature_size])
        self.lstm = nn.LSTM(self.cfg.hand_feature_size, self.cfg.hidden_size, self.cfg.num_layers, batch_first=True)
        self.output = PerDimensionMLP(MOTION_DIM, [self.cfg.hidden_size] + list(self.cfg.output_hidden) + [2])

    def _predict(self, x: torch.Tensor):
        feats = torch.relu(self.hand(self.fingers(x / self.normalizer.feature_scale)))
        h, _ = self.lstm(feats)
        out = self.output(h.unsqueeze(-2).expand(h.shape[:-1] + (MOTION_DIM, h.shape[-1])))
        scale = self.normalizer.label_scale
        return out[..., 0] * scale, bounded_std(out[..., 1], self.cfg.std_min) * scale

    def forward(self, batch: Batch, p_tf: float = 0.0, sample_posterior: bool = True,
                generator: Optional[torch.Generator] = None, x_noise_std: float = 0.0,
                nll_beta: float = 0.0) -> Dict[str, torch.Tensor]:
        """Negative log-likelihood (no latent, so the KL term is zero)."""
        x = batch.x
        if x_noise_std > 0.0:
            x = x + x_noise_std * torch.randn(x.shape, generator=generator, device=x.device)
        mean, std = self._predict(x)
        return likelihood_terms(batch, mean, std, None, self.normalizer.label_scale, nll_beta)

    @torch.no_grad()
    def predict(self, batch: Batch, z_from: str = "prior_mean", generator: Optional[torch.Generator] = None,
                keep_attention: bool = False) -> Dict[str, torch.Tensor]:
        mean, std = self._predict(batch.x)
        return {"mean": mean, "std": std}
