"""The fitted-to-the-person reference: a ridge regression solved on the user's own context."""

import numpy as np
import pytest

from rtcohand_drake.learning.ridge_reference import RidgeReference, windows


def test_windows_are_causal_and_oldest_first():
    x = np.arange(4 * 36, dtype=float).reshape(4, 36)
    w = windows(x, 3)
    assert w.shape == (4, 3 * 36)
    np.testing.assert_array_equal(w[0, :72], 0.0)  # nothing before the clip starts
    np.testing.assert_array_equal(w[2], np.concatenate([x[0], x[1], x[2]]))


def test_recovers_a_linear_map_of_the_last_frames():
    rng = np.random.default_rng(0)
    W = rng.normal(size=(2 * 36, 6))
    pieces = []
    for _ in range(8):
        x = rng.normal(size=(60, 36))
        pieces.append((x, windows(x, 2) @ W + 0.3))
    ridge = RidgeReference(window=2, lam=1e-6).fit(pieces)
    x = rng.normal(size=(40, 36))
    np.testing.assert_allclose(ridge.predict(x), windows(x, 2) @ W + 0.3, atol=1e-6)


def test_prediction_depends_only_on_the_past():
    rng = np.random.default_rng(1)
    pieces = [(rng.normal(size=(50, 36)), rng.normal(size=(50, 6))) for _ in range(4)]
    ridge = RidgeReference().fit(pieces)
    x = rng.normal(size=(30, 36))
    changed = x.copy()
    changed[20:] += 5.0
    np.testing.assert_allclose(ridge.predict(x)[:20], ridge.predict(changed)[:20])
    assert not np.allclose(ridge.predict(x)[20:], ridge.predict(changed)[20:])


def test_needs_a_context():
    with pytest.raises(ValueError):
        RidgeReference().fit([])
    with pytest.raises(RuntimeError):
        RidgeReference().predict(np.zeros((3, 36)))
