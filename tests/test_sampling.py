"""Context sampling for training and the six evaluation settings."""

import numpy as np
import pytest

from rtcohand_drake.data.dataset import PolicyClip, to_policy_clip
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.data.sampling import (
    ANGULAR_ENTRIES,
    LINEAR_ENTRIES,
    SETTINGS,
    ContextSet,
    add_feature_noise,
    collate_contexts,
    contains_dims,
    evaluation_episodes,
    sample_context,
    split_sets,
)


@pytest.fixture(scope="module")
def pcs():
    # 3 users: 2 in-sample, 1 out-sample.
    return [to_policy_clip(c) for c in generate_population(GeneratorConfig(), n_users=3, seed=1)]


def by_identity(pool, piece):
    """The pool clip whose features are ``piece`` (object identity), or None for a slice."""
    for c in pool:
        if piece[0] is c.features:
            return c
    return None


def test_settings_names():
    assert SETTINGS == ("D+U+", "D+U-", "D-U+", "D-U-", "Unseen", "Noisy")


def test_sample_context_follows_wishes(pcs):
    train, _, _ = split_sets(pcs)
    target = next(c for c in train if c.active_dims.size == 2)
    rng = np.random.default_rng(0)
    for p_d, p_u in ((1.0, 1.0), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0)):
        for _ in range(30):
            pieces = sample_context(target, train, rng, p_d=p_d, p_u=p_u)
            assert len(pieces) == 3
            chosen = by_identity(train, pieces[0])
            if chosen is None:  # a slice of the target itself: D+U+
                assert p_d == 1.0 and p_u == 1.0
                continue
            assert contains_dims(chosen, target) == (p_d == 1.0)
            assert (chosen.user == target.user) == (p_u == 1.0)
            for piece in pieces[1:]:
                other = by_identity(train, piece)
                assert other is not None and other is not target and other is not chosen


def test_sample_context_adds_clips_of_the_target_user(pcs):
    train, _, _ = split_sets(pcs)
    target = train[0]
    own = [c for c in train if c.user == target.user and c is not target]
    rng = np.random.default_rng(1)
    for _ in range(20):
        pieces = sample_context(target, train, rng, p_d=0.0, p_u=0.0, n_user=5, n_random=2)
        assert len(pieces) == 8
        chosen = by_identity(train, pieces[0])
        assert chosen is not None and chosen.user != target.user
        picked = [by_identity(train, p) for p in pieces[1:]]
        assert all(c is not None and c is not target and c is not chosen for c in picked)
        assert all(c.user == target.user for c in picked[:5])
        assert len({id(c) for c in picked}) == 7  # without replacement, across both draws
    # A user with fewer clips than asked gives what there is.
    pieces = sample_context(target, train, rng, p_d=0.0, p_u=0.0, n_user=len(own) + 10, n_random=0)
    assert len(pieces) == 1 + len(own)


def test_target_slice_bounds():
    T = 40
    feats = np.arange(T * 36, dtype=np.float32).reshape(T, 36)
    labels = np.arange(T * 6, dtype=np.float32).reshape(T, 6)
    target = PolicyClip("u", "c", "in-sample", "train", np.array([0]), feats, np.ones(T, bool), labels)
    rng = np.random.default_rng(1)
    seen = set()
    for _ in range(200):
        (piece,) = sample_context(target, [target], rng, p_d=1, p_u=1, t_min=10, p_cxt=0.5)
        k = piece[0].shape[0]
        t0 = int(piece[0][0, 0]) // 36
        assert 10 <= k and t0 + k <= 0.5 * T
        np.testing.assert_array_equal(piece[1], labels[t0 : t0 + k])
        seen.add((t0, k))
    assert len(seen) > 10  # really random


def test_collate(pcs):
    a = [(np.ones((5, 36), np.float32), np.ones((5, 6), np.float32))] * 2
    b = ContextSet([(np.zeros((3, 36), np.float32), np.full((3, 6), 2, np.float32))])
    x, y, m = collate_contexts([a, b])
    assert x.shape == (2, 10, 36) and y.shape == (2, 10, 6) and m.shape == (2, 10)
    assert m[0].all() and m[1].sum() == 3 and (y[1, :3] == 2).all() and (y[1, 3:] == 0).all()
    assert len(b) == 3


def test_noise_on_the_right_entries():
    rng = np.random.default_rng(0)
    x = add_feature_noise(np.zeros((20000, 36), np.float32), 0.05, 0.5, rng)
    assert x.dtype == np.float32
    np.testing.assert_allclose(x[:, LINEAR_ENTRIES].std(), 0.05, rtol=0.05)
    np.testing.assert_allclose(x[:, ANGULAR_ENTRIES].std(), 0.5, rtol=0.05)


@pytest.mark.parametrize("setting", SETTINGS)
def test_evaluation_rules(pcs, setting):
    train, test_in, test_out = split_sets(pcs)
    eps = evaluation_episodes(pcs, setting, seed=3)
    assert eps, setting
    train_ids = {id(c.features): c for c in train}
    for e in eps:
        assert len(e.context) == 3
        chosen = train_ids[id(e.context[0][0])]
        assert all(id(p[0]) in train_ids for p in e.context)
        if setting == "Unseen":
            assert e.target.group == "out-sample" and chosen.user != e.target.user
        else:
            assert e.target.group == "in-sample" and e.target.split == "test"
            d_plus = setting.startswith("D+") or setting == "Noisy"
            u_plus = setting.endswith("U+") or setting == "Noisy"
            assert contains_dims(chosen, e.target) == d_plus
            assert (chosen.user == e.target.user) == u_plus
        if setting == "Noisy":
            assert e.noise == (0.05, 0.025)
            assert not np.array_equal(e.target_features, e.target.features)
        else:
            assert e.target_features is e.target.features
    # In-sample settings cover every test target that has a matching context clip.
    if setting in ("D-U+", "D-U-"):
        assert len(eps) == len(test_in)
    if setting == "Unseen":
        assert len(eps) == len(test_out)


def test_own_setting_gives_the_users_other_clips(pcs):
    _, _, test_out = split_sets(pcs)
    episodes = evaluation_episodes(pcs, "Own", seed=0)
    assert len(episodes) == len(test_out) == 72
    for e in episodes[:10]:
        assert e.target.group == "out-sample" and len(e.context) == 71
        ctx = [by_identity(test_out, p) for p in e.context]
        assert all(c is not None and c.user == e.target.user and c is not e.target for c in ctx)


def test_evaluation_is_deterministic(pcs):
    a = evaluation_episodes(pcs, "Noisy", seed=7)
    b = evaluation_episodes(pcs, "Noisy", seed=7)
    c = evaluation_episodes(pcs, "Noisy", seed=8)
    assert [e.chosen for e in a] == [e.chosen for e in b]
    np.testing.assert_array_equal(a[0].target_features, b[0].target_features)
    assert [e.chosen for e in a] != [e.chosen for e in c]


def test_evaluation_on_small_files(pcs):
    in_only = [c for c in pcs if c.group == "in-sample"]
    assert evaluation_episodes(in_only, "Unseen", seed=0) == []
    one_user = [c for c in pcs if c.user == "u00"]
    assert evaluation_episodes(one_user, "D+U-", seed=0) == []
    assert len(evaluation_episodes(one_user, "D+U+", seed=0)) > 0
    assert evaluation_episodes([], "D+U+", seed=0) == []
    with pytest.raises(ValueError, match="unknown setting"):
        evaluation_episodes(pcs, "D+", seed=0)
