"""Collation of target clips and their context pieces into padded tensors with masks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np
import torch

from rtcohand_drake.data.sampling import pack_context

Piece = Tuple[np.ndarray, np.ndarray]  # (features (T, 36), labels (T, 6))


@dataclass
class Batch:
    """Targets (B, T, ..) and context pieces (B, P, Tc, ..), padded at the end.

    mask / mask_c are True on real steps. Padded steps hold zeros.
    """

    x: torch.Tensor
    y: torch.Tensor
    mask: torch.Tensor
    x_c: torch.Tensor
    y_c: torch.Tensor
    mask_c: torch.Tensor

    @property
    def size(self) -> int:
        return self.x.shape[0]

    def to(self, device: torch.device) -> "Batch":
        return Batch(*(t.to(device) for t in (self.x, self.y, self.mask, self.x_c, self.y_c, self.mask_c)))


def _finite(a: np.ndarray) -> np.ndarray:
    # Frames where the hand was not seen may carry NaN features: the model sees zeros.
    return np.nan_to_num(np.asarray(a, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)


def collate(
    targets: Sequence[Piece],
    contexts: Sequence[Sequence[Piece]],
    target_masks: Optional[Sequence[np.ndarray]] = None,
) -> Batch:
    """targets[i] = (features, labels); contexts[i] = that target's context pieces.

    target_masks[i] (T,) bool, if given, further restricts which target steps
    count in the loss (for example, steps without a label).
    """
    if len(targets) != len(contexts):
        raise ValueError("one context list per target is needed")
    if any(len(c) == 0 for c in contexts):
        raise ValueError("every target needs at least one context piece")
    b = len(targets)
    t_max = max(len(f) for f, _ in targets)
    p_max = max(len(c) for c in contexts)
    tc_max = max(len(f) for c in contexts for f, _ in c)
    x = np.zeros((b, t_max, 36), np.float32)
    y = np.zeros((b, t_max, 6), np.float32)
    mask = np.zeros((b, t_max), bool)
    x_c = np.zeros((b, p_max, tc_max, 36), np.float32)
    y_c = np.zeros((b, p_max, tc_max, 6), np.float32)
    mask_c = np.zeros((b, p_max, tc_max), bool)
    for i, (f, l) in enumerate(targets):
        n = len(f)
        x[i, :n] = _finite(f)
        y[i, :n] = _finite(l)
        mask[i, :n] = True if target_masks is None else np.asarray(target_masks[i], bool)[:n]
        for j, (fc, lc) in enumerate(contexts[i]):
            m = len(fc)
            x_c[i, j, :m] = _finite(fc)
            y_c[i, j, :m] = _finite(lc)
            mask_c[i, j, :m] = True
    if not mask_c.reshape(b, -1).any(1).all():
        raise ValueError("every target needs at least one context step")
    return Batch(*(torch.from_numpy(a) for a in (x, y, mask, x_c, y_c, mask_c)))


def collate_context(pieces: Sequence[Piece]) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """One context as the exported `encode_context` takes it: (P, Tc, 36), (P, Tc, 6), (P, Tc) bool."""
    return tuple(torch.from_numpy(a) for a in pack_context(pieces))
