"""Hand features: analytic answers for rigid motions, finger curls and lost frames."""

import numpy as np
import pytest

from rtcohand_drake.data.population import hand_keypoints_local, rotation_matrices
from rtcohand_drake.data.hand_features import (
    FEATURE_DIM,
    PARTS,
    HandFeatureStream,
    hand_features,
    part_frames,
    part_velocities,
    resample,
)

FPS = 30.0
RATE = 10.0


def reference_hand(curl=0.2):
    """A relaxed right hand, palm down, fingers along +Y, wrist at (0.1, 0.3, 0)."""
    n = 1
    kp = hand_keypoints_local(
        np.full((n, 4), curl), np.zeros((n, 4)), np.deg2rad([[40.0, 20.0, 15.0, 10.0]]), 1.0
    )[0]
    return kp + np.array([0.1, 0.3, 0.0])


def split(x):
    x = x.reshape(-1, 6, 6)
    return x[:, :, :3], x[:, :, 3:]


def test_api_constants():
    assert PARTS == ("palm", "thumb", "index", "middle", "ring", "pinky")
    assert FEATURE_DIM == 36


def test_part_frames_are_rotations_and_palm_axes_match_docstring():
    R, o = part_frames(reference_hand()[None])
    assert R.shape == (1, 6, 3, 3) and o.shape == (1, 6, 3)
    eye = np.einsum("npji,npjk->npik", R, R)
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(3), eye.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # Palm down, fingers forward: e_y = +Y, e_z = -Z (out of the palm), e_x = -X (thumb side).
    # (The middle MCP sits slightly toward the thumb, so e_y leans a few degrees.)
    np.testing.assert_allclose(R[0, 0], [[-1, 0, 0], [0, 1, 0], [0, 0, -1]], atol=0.1)


def test_rigid_translation_same_linear_velocity_zero_angular():
    v = np.array([0.12, -0.05, 0.08])
    t = np.arange(46) / FPS
    kp = reference_hand()[None] + t[:, None, None] * v
    x, valid = hand_features(kp, FPS, RATE)
    assert x.shape == (16, 36) and x.dtype == np.float32 and valid.all()
    lin, ang = split(x[1:])
    np.testing.assert_allclose(lin, np.broadcast_to(v, lin.shape), atol=1e-5)
    np.testing.assert_allclose(ang, 0.0, atol=1e-5)
    np.testing.assert_array_equal(x[0], 0.0)


@pytest.mark.parametrize("axis", [[0, 0, 1], [1, 0, 0], [0.3, -0.8, 0.5]])
def test_rigid_rotation_gives_axis_rate_and_chord_velocities(axis):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    rate = 0.9  # rad/s
    centre = np.array([0.05, 0.25, -0.02])
    t = np.arange(46) / FPS
    hand = reference_hand()
    Rt = rotation_matrices(np.outer(rate * t, k))
    kp = centre + np.einsum("nij,kj->nki", Rt, hand - centre)
    x, valid = hand_features(kp, FPS, RATE)
    assert valid.all()
    lin, ang = split(x[1:])
    np.testing.assert_allclose(ang, np.broadcast_to(rate * k, ang.shape), atol=1e-4)
    # Linear: each part origin rotates about the centre; over one policy period it moves
    # along the chord (R(t_k) - R(t_{k-1})) (o_0 - c).
    _, o0 = part_frames(hand[None])
    tk = np.arange(16) / RATE
    Rk = rotation_matrices(np.outer(rate * tk, k))
    pos = centre + np.einsum("nij,pj->npi", Rk, o0[0] - centre)
    expected = np.diff(pos, axis=0) * RATE
    np.testing.assert_allclose(lin, expected, atol=1e-5)
    # And it is close to the instantaneous w x (o - c) at the chord's midpoint.
    assert np.abs(lin).max() > 0.01


def test_curling_one_finger_moves_only_that_finger():
    t = np.arange(31) / FPS
    n = t.size
    curl = np.full((n, 4), 0.2)
    curl[:, 1] = 0.2 + 0.6 * t / t[-1]  # middle finger curls
    local = hand_keypoints_local(curl, np.zeros((n, 4)), np.tile(np.deg2rad([40.0, 20.0, 15.0, 10.0]), (n, 1)), 1.0)
    x, valid = hand_features(local, FPS, RATE)
    assert valid.all()
    parts = np.abs(x[1:].reshape(-1, 6, 6)).max(axis=(0, 2))
    middle = PARTS.index("middle")
    assert parts[middle] > 0.5  # rad/s of flexion, well above noise
    others = np.delete(parts, middle)
    np.testing.assert_allclose(others, 0.0, atol=1e-6)
    # The middle finger turns about the palm's across axis (X): flexion.
    ang = x[1:].reshape(-1, 6, 6)[:, middle, 3:]
    assert np.all(np.abs(ang[:, 0]) > 10 * np.abs(ang[:, 1:]).max(axis=1))


def test_lost_frames_give_zeros_and_false_flag():
    v = np.array([0.1, 0.0, 0.0])
    t = np.arange(61) / FPS
    kp = reference_hand()[None] + t[:, None, None] * v
    kp[15:30] = np.nan  # 0.5 s without a hand
    x, valid = hand_features(kp, FPS, RATE)
    assert np.isfinite(x).all()
    assert not valid[5] and not valid[6] and not valid[9]
    assert valid[:5].all() and valid[11:].all()
    np.testing.assert_array_equal(x[~valid], 0.0)
    # Samples 5..9 (0.5..0.9 s) have no pose or no previous pose; 10 (1.0 s) lost its predecessor.
    np.testing.assert_array_equal(np.flatnonzero(~valid), [5, 6, 7, 8, 9, 10])
    # A single dropped frame at 30 Hz is bridged by interpolation.
    kp2 = reference_hand()[None] + t[:, None, None] * v
    kp2[16] = np.nan
    x2, valid2 = hand_features(kp2, FPS, RATE)
    assert valid2.all()
    np.testing.assert_allclose(split(x2[1:])[0], np.broadcast_to(v, (20, 6, 3)), atol=1e-5)


def test_all_lost_and_empty():
    kp = np.full((20, 21, 3), np.nan, np.float32)
    x, valid = hand_features(kp, FPS, RATE)
    assert not valid.any() and np.all(x == 0)
    x, valid = hand_features(np.zeros((0, 21, 3)), FPS, RATE)
    assert x.shape == (0, 36) and valid.shape == (0,)
    with pytest.raises(ValueError):
        hand_features(np.zeros((5, 20, 3)), FPS)


def test_timestamps_and_other_rates():
    v = np.array([0.0, 0.1, -0.1])
    rng = np.random.default_rng(0)
    ts = np.cumsum(rng.uniform(0.02, 0.045, size=80))  # irregular camera clock
    kp = reference_hand()[None] + (ts - ts[0])[:, None, None] * v
    x, valid = hand_features(kp, 30.0, 20.0, timestamps=ts)
    assert x.shape[0] == int(np.floor((ts[-1] - ts[0]) * 20 + 1e-6)) + 1
    lin, ang = split(x[1:][valid[1:]])
    np.testing.assert_allclose(lin, np.broadcast_to(v, lin.shape), atol=1e-5)


def test_resample_is_linear_interpolation_on_policy_times():
    times = np.arange(31) / 30.0
    values = np.stack([times, 2 * times + 1], axis=1)
    out, new_t = resample(values, times, 10.0)
    np.testing.assert_allclose(new_t, np.arange(11) / 10.0)
    np.testing.assert_allclose(out, np.stack([new_t, 2 * new_t + 1], axis=1), atol=1e-12)
    # The same sample times as the features.
    x, _ = hand_features(np.zeros((31, 21, 3)) + reference_hand(), 30.0, 10.0)
    assert x.shape[0] == out.shape[0]


def test_stream_matches_batch_and_handles_lost_hand():
    v = np.array([0.05, 0.02, 0.0])
    t = np.arange(31) / FPS
    kp = reference_hand()[None] + t[:, None, None] * v
    batch, _ = hand_features(kp, FPS, RATE)
    stream = HandFeatureStream()
    outs = [stream.update(kp[3 * k], 3 * k / FPS) for k in range(11)]
    assert outs[0][1] is False
    np.testing.assert_allclose(np.stack([o[0] for o in outs[1:]]), batch[1:], atol=1e-6)
    x, ok = stream.update(np.full((21, 3), np.nan), 1.1)
    assert not ok and np.all(x == 0)
    x, ok = stream.update(kp[0], 1.2)
    assert not ok  # needs two poses after a lost hand


def test_part_velocities_shapes():
    R, o = part_frames(np.stack([reference_hand()] * 4))
    x = part_velocities(R[:-1], o[:-1], R[1:], o[1:], 0.1)
    assert x.shape == (3, 36)
    np.testing.assert_allclose(x, 0.0, atol=1e-9)
