"""The third fitted-to-the-person reference: a Gaussian-kernel ridge read of the hand's path and shape.

From exactly the context a policy gets (the user's labelled clips, with the hand's path and shape after
the 36 velocities: `to_policy_clip(path_shape=True)`), it reads each step's twist as a kernel ridge
regression over the path-and-shape columns: standardised by the context's steps, a Gaussian kernel
whose bandwidth is `bandwidth` x the median distance between the context's steps, `lam` on the
diagonal, the labels' context mean the read with no evidence. One linear solve, no training. It is
the read the shipped policy file blends with the CCHP (`learning.path_shape_policy`), alone;
its settings were chosen on recorded development people (docs/real_people.md, section 4).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rtcohand_drake.data.hand_features import FEATURE_DIM

BANDWIDTH, LAMBDA = 0.5, 0.3


class KernelReference:
    """Fit on [(features (T, F), labels (T, 6)), ...]; predict a (T, 6) twist for a (T, F) stream, reading
    the columns from `start` on (by default those after the 36 velocities)."""

    def __init__(self, bandwidth: float = BANDWIDTH, lam: float = LAMBDA, start: int = FEATURE_DIM,
                 standardise: bool = True):
        if not (bandwidth > 0 and lam > 0):
            raise ValueError(f"need bandwidth > 0 and lambda > 0, got {bandwidth}, {lam}")
        self.bandwidth, self.lam, self.start, self.standardise = float(bandwidth), float(lam), int(start), standardise
        self.keys = None

    def _scaled(self, x: np.ndarray) -> np.ndarray:
        return (np.nan_to_num(np.asarray(x, np.float64)[:, self.start:]) - self.mean) / self.spread

    def fit(self, pieces: Sequence[tuple[np.ndarray, np.ndarray]]) -> "KernelReference":
        import torch

        pieces = [(x, y) for x, y in pieces if len(x)]
        if not pieces:
            raise ValueError("the reference needs at least one labelled context clip")
        if np.shape(pieces[0][0])[1] <= self.start:
            raise ValueError(f"the kernel reference reads the columns from {self.start} on (the hand's path and "
                             f"shape: to_policy_clip(path_shape=True)); the features have {np.shape(pieces[0][0])[1]}")
        s = np.concatenate([np.nan_to_num(np.asarray(x, np.float64)[:, self.start:]) for x, _ in pieces])
        y = np.concatenate([np.nan_to_num(np.asarray(l, np.float64)) for _, l in pieces])
        self.mean, self.spread = (s.mean(0), s.std(0) + 1e-6) if self.standardise else (0.0, 1.0)
        self.keys = torch.from_numpy(self._scaled(np.hstack([np.zeros((len(s), self.start)), s])))
        distance = torch.cdist(self.keys, self.keys)
        apart = distance[distance > 0]
        self.width = self.bandwidth * (float(np.median(apart.numpy())) if apart.numel() else 1.0)
        gram = torch.exp(-distance ** 2 / (2 * self.width ** 2)).numpy()
        self.offset = y.mean(0)
        self.weights = np.linalg.solve(gram + self.lam * np.eye(len(gram)), y - self.offset)
        return self

    def predict(self, x: np.ndarray) -> np.ndarray:
        import torch

        if self.keys is None:
            raise RuntimeError("fit the reference first")
        near = torch.cdist(torch.from_numpy(self._scaled(x)), self.keys)
        return self.offset + torch.exp(-near ** 2 / (2 * self.width ** 2)).numpy() @ self.weights
