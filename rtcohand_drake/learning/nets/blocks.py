"""Small building blocks shared by CCHP and the baselines.

Motion dimensions are ordered Tx, Ty, Tz, Rx, Ry, Rz; hand parts palm, thumb,
index, middle, ring, pinky (6 parts x 6-D velocity = 36 features).
"""

from __future__ import annotations

import math
from typing import List, Sequence

import torch
from torch import nn

from rtcohand_drake.data.hand_features import FEATURE_DIM, PART_DIM, PARTS  # noqa: F401  (numpy only)

NUM_PARTS = len(PARTS)
MOTION_DIM = 6


def mlp(sizes: Sequence[int]) -> nn.Sequential:
    """An MLP given as [input, hidden..., output].

    A ReLU follows the input layer and every hidden layer, none follows the
    output layer (paper appendix, "Model Architecture").
    """
    if len(sizes) < 2:
        raise ValueError(f"an MLP needs at least input and output sizes, got {list(sizes)}")
    layers: List[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class PerDimensionMLP(nn.Module):
    """`n` independent MLPs of the same sizes evaluated as one batched matmul.

    Input (..., n, in), output (..., n, out); one network per motion dimension.
    """

    def __init__(self, n: int, sizes: Sequence[int]):
        super().__init__()
        self.n = n
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for i in range(len(sizes) - 1):
            fan_in, fan_out = sizes[i], sizes[i + 1]
            bound = 1.0 / math.sqrt(fan_in)
            self.weights.append(nn.Parameter(torch.empty(n, fan_in, fan_out).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(torch.empty(n, fan_out).uniform_(-bound, bound)))
        self.num_layers = len(sizes) - 1

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        i = 0
        for w, b in zip(self.weights, self.biases):
            # (..., n, in) x (n, in, out) -> (..., n, out)
            x = torch.einsum("...ni,nio->...no", x, w) + b
            if i < self.num_layers - 1:
                x = torch.relu(x)
            i += 1
        return x


def bounded_std(raw: torch.Tensor, std_min: float) -> torch.Tensor:
    """A standard deviation bounded from below: std_min + (1 - std_min) * softplus.

    An unbounded std lets the likelihood collapse onto the training labels.
    """
    return std_min + (1.0 - std_min) * nn.functional.softplus(raw)


def gaussian_log_prob(y: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """Elementwise log N(y; mean, std^2)."""
    return -0.5 * ((y - mean) / std) ** 2 - torch.log(std) - 0.5 * math.log(2.0 * math.pi)


def gaussian_kl(mu_q: torch.Tensor, sigma_q: torch.Tensor, mu_p: torch.Tensor, sigma_p: torch.Tensor) -> torch.Tensor:
    """KL(N(mu_q, sigma_q^2) || N(mu_p, sigma_p^2)) summed over the last axis."""
    var_ratio = (sigma_q / sigma_p) ** 2
    kl = 0.5 * (var_ratio + ((mu_q - mu_p) / sigma_p) ** 2 - 1.0 - torch.log(var_ratio))
    return kl.sum(-1)


class Normalizer(nn.Module):
    """Fixed per-channel scales (set from the training data) kept in the model.

    The model sees features / feature_scale and labels / label_scale, so the
    exported policy takes and returns physical units (m/s, rad/s).
    """

    def __init__(self):
        super().__init__()
        self.register_buffer("feature_scale", torch.ones(FEATURE_DIM))
        self.register_buffer("label_scale", torch.ones(MOTION_DIM))

    def set_scales(self, feature_scale: torch.Tensor, label_scale: torch.Tensor) -> None:
        self.feature_scale.copy_(torch.as_tensor(feature_scale, dtype=torch.float32).clamp_min(1e-6))
        self.label_scale.copy_(torch.as_tensor(label_scale, dtype=torch.float32).clamp_min(1e-6))

