"""The fitted-to-the-person reference: a ridge regression solved on the user's own context.

The bar a context read must clear. From exactly the context a policy gets
(the user's labelled clips), it fits a linear map from the last `window`
frames of the 36 hand-part velocities (standardised over the context) to the
six twist labels, with an unpenalised intercept:

    W = (Xs^T Xs + lam I)^-1 Xs^T (Y - mean(Y))

for `window` x 36 inputs per step (10 x 36 = 360 at 10 Hz: the last second).
It is causal (each step sees only the past, with zeros before a clip starts)
and needs no training beyond the solve, so it is what a model fitted to the
person does with the same clips. Numpy only.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rtcohand_drake.data.hand_features import FEATURE_DIM

MOTION_DIM = 6


def windows(x: np.ndarray, window: int) -> np.ndarray:
    """(T, 36) features -> (T, window * 36): at each step the last `window` frames, oldest first, zero-padded."""
    x = np.nan_to_num(np.asarray(x, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    padded = np.concatenate([np.zeros((window - 1, x.shape[1])), x])
    return np.stack([padded[k : k + len(x)] for k in range(window)], axis=1).reshape(len(x), -1)


class RidgeReference:
    """Fit on [(features (T, 36), labels (T, 6)), ...]; predict a (T, 6) twist for a (T, 36) stream."""

    def __init__(self, window: int = 10, lam: float = 100.0):
        if window < 1 or lam < 0:
            raise ValueError(f"need window >= 1 and lam >= 0, got {window}, {lam}")
        self.window, self.lam = int(window), float(lam)
        self.coef = None

    def fit(self, pieces: Sequence[tuple[np.ndarray, np.ndarray]]) -> "RidgeReference":
        pieces = [(x, y) for x, y in pieces if len(x)]
        if not pieces:
            raise ValueError("the reference needs at least one labelled context clip")
        X = np.concatenate([windows(x, self.window) for x, _ in pieces])
        Y = np.concatenate([np.nan_to_num(np.asarray(y, np.float64)) for _, y in pieces])
        self.x_mean = X.mean(0)
        self.x_scale = np.maximum(X.std(0), 1e-6)
        self.y_mean = Y.mean(0)
        Xs = (X - self.x_mean) / self.x_scale
        A = Xs.T @ Xs + self.lam * np.eye(Xs.shape[1])
        self.coef = np.linalg.solve(A, Xs.T @ (Y - self.y_mean))
        return self

    def predict(self, x: np.ndarray) -> np.ndarray:
        if self.coef is None:
            raise RuntimeError("fit the reference first")
        Xs = (windows(x, self.window) - self.x_mean) / self.x_scale
        return Xs @ self.coef + self.y_mean
