"""The second fitted-to-the-person reference: a nearest-neighbour read of the hand's recent motion.

From exactly the context a policy gets (the user's labelled clips), it
predicts each step's twist as the mean label of the `k` context steps whose
recent hand motion is nearest. The motion at step t is, for each lag
j = 1 .. `window`, the sum of the last j frames of the 36 hand-part velocities
(the net motion of every part over the last j steps, so the descriptor holds
the shape of the stroke so far, not only its speed), each entry standardised
over the context's steps. It is causal (zeros before a clip starts), needs no
training beyond storing the context, and it reads any function of the recent
motion, where the ridge (`ridge_reference`) reads only linear ones: strokes
with a return, whose sum over the window is near zero, are the case where the
two differ. Numpy and torch's `cdist` only.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rtcohand_drake.learning.ridge_reference import windows


def net_motions(x: np.ndarray, window: int) -> np.ndarray:
    """(T, F) features -> (T, window * F): at each step, for j = 1 .. window, the sum of the last j frames."""
    x = np.asarray(x, np.float64)
    frames = windows(x, window).reshape(len(x), window, x.shape[1])[:, ::-1]  # newest first
    return np.cumsum(frames, axis=1).reshape(len(x), -1)


class KnnReference:
    """Fit on [(features (T, 36), labels (T, 6)), ...]; predict a (T, 6) twist for a (T, 36) stream."""

    def __init__(self, window: int = 20, k: int = 20):
        if window < 1 or k < 1:
            raise ValueError(f"need window >= 1 and k >= 1, got {window}, {k}")
        self.window, self.k = int(window), int(k)
        self.keys = None

    def fit(self, pieces: Sequence[tuple[np.ndarray, np.ndarray]]) -> "KnnReference":
        pieces = [(x, y) for x, y in pieces if len(x)]
        if not pieces:
            raise ValueError("the reference needs at least one labelled context clip")
        X = np.concatenate([net_motions(x, self.window) for x, _ in pieces])
        self.labels = np.concatenate([np.nan_to_num(np.asarray(y, np.float64)) for _, y in pieces])
        self.scale = np.maximum(X.std(0), 1e-6)
        self.keys = X / self.scale
        return self

    def predict(self, x: np.ndarray, chunk: int = 256) -> np.ndarray:
        import torch

        if self.keys is None:
            raise RuntimeError("fit the reference first")
        queries = torch.from_numpy(net_motions(x, self.window) / self.scale)
        keys = torch.from_numpy(self.keys)
        k = min(self.k, len(self.keys))
        out = np.zeros((len(queries), self.labels.shape[1]))
        for i in range(0, len(queries), chunk):
            nearest = torch.topk(torch.cdist(queries[i:i + chunk], keys), k, largest=False).indices.numpy()
            out[i:i + chunk] = self.labels[nearest].mean(1)
        return out
