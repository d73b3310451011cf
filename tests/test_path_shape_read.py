"""The hand's path and shape, and the policy file that reads them with a kernel beside the CCHP."""

import numpy as np
import pytest
import torch
from pydrake.systems.analysis import Simulator

from rtcohand_drake.data.dataset import load_policy_clips, read_dataset, to_policy_clip, write_dataset
from rtcohand_drake.data.hand_features import (FEATURE_DIM, PATH_SHAPE_DIM, PathShapeStream, hand_features,
                                               path_shape_features)
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.data.sampling import pack_context
from rtcohand_drake.errors import InputError
from rtcohand_drake.interfaces import KEYPOINTS
from rtcohand_drake.learning.path_shape_policy import PathShapeKernelPolicy, build_path_shape_policy
from rtcohand_drake.learning.policy_file import load_policy

LAGS = (0, 4, 8, 12, 16)  # 0, 0.4, .. 1.6 s at 10 Hz
NO_MATCH = (0.0, 50.0, 0.05)  # the kernel read alone, without the stroke matched by a time warp


def _expected_path_shape(samples, median):
    """The features written out from their definition: held samples, a causal median, lags clamped."""
    held, last = [], None
    for s in samples:
        last = s if np.isfinite(s).all() else last
        held.append(last)
    out = []
    for i in range(len(held)):
        filtered = [np.median(np.stack(held[max(0, j - median + 1):j + 1]), axis=0) for j in range(i + 1)]
        centre = filtered[i].mean(axis=0)
        out.append(np.concatenate([(filtered[max(i - lag, 0)] - centre).reshape(-1) for lag in LAGS]))
    return np.array(out)


@pytest.mark.parametrize("median", [1, 3])
def test_stream_follows_the_definition_through_a_lost_hand(median):
    rng = np.random.default_rng(median)
    samples = [rng.normal(size=(21, 3)) for _ in range(30)]
    samples[7] = np.full((21, 3), np.nan)  # the hand lost for two samples: the last seen one is held
    samples[8] = np.full((21, 3), np.nan)
    stream = PathShapeStream(10.0, median)
    assert stream.update(np.full((21, 3), np.nan)) == (pytest.approx(np.zeros(PATH_SHAPE_DIM)), False)  # none seen
    got = np.array([stream.update(s)[0] for s in samples])
    assert got.shape == (30, PATH_SHAPE_DIM)
    assert np.allclose(got, _expected_path_shape(samples, median), atol=1e-5)
    stream.reset()
    assert np.allclose(stream.update(samples[0])[0], _expected_path_shape(samples[:1], median)[0], atol=1e-6)


def test_a_hand_moving_sideways_shows_its_path_at_each_lag():
    """A rigid hand moving along X at 0.2 m/s: every lag's keypoints sit 0.2 m/s x lag behind, shape kept."""
    rng = np.random.default_rng(0)
    hand = rng.normal(scale=0.03, size=(21, 3))
    t = np.arange(90) / 30.0  # 3 s at 30 frames/s
    keypoints = hand[None] + np.outer(0.2 * t, [1.0, 0.0, 0.0])[:, None, :]
    x = path_shape_features(keypoints, 30.0)
    assert x.shape == (len(hand_features(keypoints, 30.0)[0]), PATH_SHAPE_DIM)
    shape = hand - hand.mean(axis=0)
    step = 25  # 2.5 s: every lag reaches back into the clip
    for i, lag in enumerate(LAGS):
        expected = shape - np.array([0.2 * lag / 10.0, 0.0, 0.0])
        assert np.allclose(x[step, 63 * i:63 * (i + 1)].reshape(21, 3), expected, atol=1e-5)


def _inner_policy(tmp_path):
    """A real TorchScript export of a small CCHP model with the Bayesian linear read and a label lead."""
    from rtcohand_drake.learning.export import export_model
    from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig

    torch.manual_seed(0)
    model = Cchp(CchpConfig(hidden_size=32, aggregate_sizes=[32, 32], latent_trunk_sizes=[32, 32], latent_dim=8,
                            key_size=16, output_hidden=[32], key_source="gesture", attention_kernel="distance",
                            read_skip=True, read="bayes_linear", label_lead=2)).eval()
    return export_model(model, {"kind": "cchp", "note": "a small untrained model for tests"}, tmp_path / "inner.pt")


def _pieces(rng, lengths):
    return [(np.hstack([rng.normal(scale=0.3, size=(n, FEATURE_DIM)), rng.normal(scale=0.05, size=(n, PATH_SHAPE_DIM))])
             .astype(np.float32), rng.normal(scale=0.1, size=(n, 6)).astype(np.float32)) for n in lengths]


def _kernel_read(context, query, bandwidth, lam, embed=lambda s: s):
    """Gaussian-kernel ridge over the standardised path-and-shape columns (or their `embed`), written out in numpy."""
    s = embed(np.concatenate([x[:, FEATURE_DIM:] for x, _ in context])).astype(np.float64)
    y = np.concatenate([l for _, l in context]).astype(np.float64)
    mean, spread = s.mean(0), s.std(0) + 1e-6
    s = (s - mean) / spread
    d = np.sqrt(((s[:, None] - s[None]) ** 2).sum(-1))
    apart = np.sort(d[d > 0])
    width = bandwidth * apart[(len(apart) - 1) // 2]  # the lower median, as torch.median
    weights = np.linalg.solve(np.exp(-d ** 2 / (2 * width ** 2)) + lam * np.eye(len(s)), y)
    q = (embed(query[:, FEATURE_DIM:]).astype(np.float64) - mean) / spread
    near = np.sqrt(((q[:, None] - s[None]) ** 2).sum(-1))
    return np.exp(-near ** 2 / (2 * width ** 2)) @ weights


def test_policy_file_blends_the_cchp_with_a_kernel_read_of_the_context(tmp_path):
    inner_path = _inner_policy(tmp_path)
    path = build_path_shape_policy(inner_path, tmp_path / "wide.pt", blend=0.7, bandwidth=0.6, lam=0.4, folds=0,
                                   commit=(0.0, 0.2, 0.6), match=NO_MATCH)
    module = load_policy(path)  # torch.jit.load alone, with the checks the software makes
    inner = load_policy(inner_path)
    assert int(module.feature_dim) == FEATURE_DIM + PATH_SHAPE_DIM
    assert int(module.hidden_size) == int(inner.hidden_size) + 6
    rng = np.random.default_rng(1)
    context, (target, _) = _pieces(rng, [30, 22, 17]), _pieces(rng, [12])[0]
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
    inner_keys, inner_values, inner_z, _ = inner.encode_context(x_c[:, :, :FEATURE_DIM].contiguous(), y_c, mask)
    assert torch.equal(values, inner_values) and torch.equal(z_mu, inner_z) and keys.shape[0] == 69
    kernel = _kernel_read(context, target, 0.6, 0.4)
    H = int(module.hidden_size)
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    hi, ci, yi = torch.zeros(H - 6), torch.zeros(H - 6), torch.zeros(6)
    with torch.no_grad():
        for t, x in enumerate(target):
            x = torch.from_numpy(x)
            mean, std, h, c, attention = module.step(x, y, h, c, keys, values, z_mu)
            mean_i, std_i, hi, ci, _, _, query_i = inner.step_read(x[:FEATURE_DIM], yi, hi, ci, inner_keys,
                                                                   inner_values, inner_z)
            yi, y = mean_i, mean  # the inner policy is fed its own mean, whatever the caller feeds back
            expected = 0.7 * kernel[t] + 0.3 * mean_i.numpy()
            assert np.allclose(mean.numpy(), expected, atol=2e-4), (t, mean.numpy(), expected)
            assert torch.allclose(std, std_i)
            # The attention: 0.7 of the kernel read's equivalent kernel, 0.3 of the CCHP's.
            kernel_attention = (attention - 0.3 * inner.attention_of(query_i, inner_keys)) / 0.7
            y_all = np.concatenate([l for _, l in context]).astype(np.float64)
            assert np.allclose(kernel_attention.numpy() @ y_all, kernel[t], atol=2e-4)
    with pytest.raises(Exception, match="x_c must be"):  # torch.jit.Error carries the RuntimeError
        module.encode_context(x_c[:, :, :FEATURE_DIM + 4].contiguous(), y_c, mask)


def test_cross_validated_blend_matches_refitting_without_each_fold(tmp_path):
    """With --folds, A is the least-squares blend of the two reads over the person's own clips, each
    read with the other folds' clips as context: here the kernel read is refitted from scratch."""
    inner_path = _inner_policy(tmp_path)
    path = build_path_shape_policy(inner_path, tmp_path / "cv.pt", bandwidth=0.6, lam=0.01, folds=3,
                                   commit=(0.0, 0.2, 0.6), match=NO_MATCH, min_gain=0.0, min_fast_turns=0.0)
    module, inner = load_policy(path), load_policy(inner_path)
    rng = np.random.default_rng(7)
    context = _pieces(rng, [14, 9, 12, 11, 8])
    for x, y in context:  # labels the path and shape tell: the kernel read should win some weight
        y[:] = np.tanh(x[:, FEATURE_DIM:FEATURE_DIM + 6] * 10.0) * 0.02 + y
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, _, _, _ = module.encode_context(x_c, y_c, mask)
    s_all = np.concatenate([x[:, FEATURE_DIM:] for x, _ in context]).astype(np.float64)
    y_all = np.concatenate([y for _, y in context]).astype(np.float64)
    mean, spread = s_all.mean(0), s_all.std(0) + 1e-6
    standard = (s_all - mean) / spread
    d = np.sqrt(((standard[:, None] - standard[None]) ** 2).sum(-1))
    apart = np.sort(d[d > 0])
    width = 0.6 * apart[(len(apart) - 1) // 2]
    starts = np.cumsum([0] + [len(x) for x, _ in context])
    sums = np.zeros((5, 3))  # per clip: (k - c).(y - c), |k - c|^2, |y - c|^2
    for f in range(3):
        out = [b for b in range(5) if b % 3 == f]
        rows = [b for b in range(5) if b % 3 != f]
        fit = np.concatenate([np.arange(starts[b], starts[b + 1]) for b in rows])
        gram = np.exp(-d[np.ix_(fit, fit)] ** 2 / (2 * width ** 2))
        weights = np.linalg.solve(gram + 0.01 * np.eye(len(fit)), y_all[fit])
        kept = [context[b] for b in rows]
        kx, ky, km = (torch.from_numpy(a) for a in pack_context([(x[:, :FEATURE_DIM], y) for x, y in kept]))
        ikeys, ivalues, iz, _ = inner.encode_context(kx, ky, km)
        for b in out:
            span = np.arange(starts[b], starts[b + 1])
            kernel = np.exp(-d[np.ix_(span, fit)] ** 2 / (2 * width ** 2)) @ weights
            H = int(inner.hidden_size)
            h, c, y_prev = torch.zeros(H), torch.zeros(H), torch.zeros(6)
            with torch.no_grad():
                for t, x in enumerate(context[b][0]):
                    y_prev, _, h, c, _, _, _ = inner.step_read(torch.from_numpy(x[:FEATURE_DIM]), y_prev, h, c, ikeys,
                                                               ivalues, iz)
                    cchp = y_prev.numpy().astype(np.float64)
                    sums[b] += [(kernel[t] - cchp) @ (y_all[span[t]] - cchp), (kernel[t] - cchp) @ (kernel[t] - cchp),
                                (y_all[span[t]] - cchp) @ (y_all[span[t]] - cchp)]
    num, den, base = sums.sum(0)
    expected = float(np.clip(num / den, 0.0, 1.0))
    assert 0.05 < expected < 0.999  # a blend, not a bound
    assert float(module._blend(keys)) == pytest.approx(expected, abs=2e-4)
    # The gain: the share of the CCHP's squared error over those steps that the blend removes, each of
    # two halves of the clips (alternate ones) read with the A fitted on the other half:
    # |y - (A k + (1 - A) c)|^2 = |y - c|^2 - 2 A (k - c).(y - c) + A^2 |k - c|^2, summed over the steps.
    halves = [sums[0::2].sum(0), sums[1::2].sum(0)]
    blend_error = 0.0
    for i in (0, 1):
        other_a = float(np.clip(halves[1 - i][0] / halves[1 - i][1], 0.0, 1.0))
        blend_error += halves[i][2] - 2 * other_a * halves[i][0] + other_a ** 2 * halves[i][1]
    used, fitted, gain, cchp_error = (float(v) for v in module.blend_choice(keys))
    assert used == fitted == pytest.approx(expected, abs=2e-4)
    assert gain == pytest.approx(1.0 - blend_error / base, abs=2e-4)
    # The CCHP's own squared error over those steps, as a share of commanding zero twist's.
    assert cchp_error == pytest.approx(base / float((y_all ** 2).sum()), rel=1e-4)


def test_bad_settings_and_wide_inner_files_are_one_line_errors(tmp_path):
    inner_path = _inner_policy(tmp_path)
    with pytest.raises(InputError, match="blend must be in"):
        build_path_shape_policy(inner_path, tmp_path / "bad.pt", blend=1.5)
    wide = build_path_shape_policy(inner_path, tmp_path / "wide.pt")
    with pytest.raises(InputError, match="already reads 351 features"):
        build_path_shape_policy(wide, tmp_path / "twice.pt")


@pytest.fixture(scope="module")
def person_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "two_users.h5"
    write_dataset(path, list(generate_population(GeneratorConfig(), n_users=2, seed=3)))
    return path


def test_the_policy_box_reads_the_sources_skeleton_as_the_file_does_offline(tmp_path, person_file):
    """In the run diagram, the box turns the replayed skeleton into the path and shape itself; its
    twist is the module's, stepped offline on the clip's features. (The file's gates are off, so that this
    simulated person gets the kernel read, and must bring the path and shape.)"""
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.data.hand_features import resample
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.replay import ReplayGestureSource
    from rtcohand_drake.systems.policy import CchpPolicy

    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "wide.pt", min_cchp_error=0.0,
                                   min_fast_turns=0.0)
    raw = read_dataset(person_file)
    target = raw[0]
    wide = [to_policy_clip(c, 10.0, path_shape=True) for c in raw[1:6] if c.user == target.user]
    pieces = [(c.features, c.labels) for c in wide]
    narrow = [(c.features[:, :FEATURE_DIM], c.labels) for c in wide]
    with pytest.raises(InputError, match="reads 351 features per step, the context pieces have \\[36\\]"):
        CchpPolicy(path, narrow, 10.0)
    scenario = load_scenario("inspection")
    policy = CchpPolicy(path, pieces, 10.0, seed=4)
    assert policy.HasInputPort(KEYPOINTS)
    clip = to_policy_clip(target, 10.0, path_shape=True)
    skeleton = resample(target.keypoints.reshape(len(target.keypoints), -1).astype(float), target.times, 10.0)[0]
    source = ReplayGestureSource([to_policy_clip(target, 10.0)], 10.0, [skeleton])
    run = build_run_diagram(scenario, source=source, policy=policy)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(source.end_time)
    log = run.loggers["policy_mean"].FindLog(simulator.get_context())
    module = load_policy(path)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
    keys, values, _, _ = module.encode_context(x_c, y_c, mask)
    assert float(module.blend_choice(keys)[0]) > 0.0  # the kernel read is used
    H = int(module.hidden_size)
    h, c, y, z = torch.zeros(H), torch.zeros(H), torch.zeros(6), torch.from_numpy(policy.sample_z(0).astype(np.float32))
    # The replayed skeleton, as the box sees it, through the stream (the file's own path-and-shape
    # features interpolate across the simulated camera's dropped frames differently), with the box's
    # jump guard and fresh paths after a loss, and its rest release (learning.rest_release).
    from rtcohand_drake.learning.rest_release import guard_stream

    features = guard_stream(policy.release, clip.features[:, :FEATURE_DIM], skeleton.reshape(len(skeleton), 21, 3))
    offline = []
    with torch.no_grad():
        for x in features.astype(np.float32):
            y, _, h, c, _ = module.step(torch.from_numpy(x), y, h, c, keys, values, z)
            offline.append(y.numpy().copy())
    offline = np.array(offline) * policy.release.gates(features)[:, None]
    k = np.round(log.sample_times() * 10.0).astype(int) - 1  # a sample at k/rate shows the update at (k-1)/rate
    ok = (k >= 1) & (k < len(offline))
    assert ok.sum() >= len(offline) - 3 and np.abs(offline).max() > 1e-3
    assert np.max(np.abs(log.data().T[ok] - offline[k[ok]])) < 1e-4


def test_the_shipped_path_shape_file_is_the_shipped_cchp_with_the_chosen_read():
    """models/cchp_path_shape.pt is `path_shape_policy` applied to models/cchp_default.pt with its defaults."""
    import pathlib

    from rtcohand_drake.learning import path_shape_policy as psp
    from rtcohand_drake.learning.export import read_model_card

    models = pathlib.Path(__file__).resolve().parents[1] / "models"
    card = read_model_card(models / "cchp_path_shape.pt")
    assert card["path_shape_read"] == {
        "inner_policy": "cchp_default.pt", "blend": psp.DEFAULT_BLEND, "bandwidth": psp.DEFAULT_BANDWIDTH,
        "lambda": psp.DEFAULT_LAMBDA, "blend_folds": psp.DEFAULT_CV_FOLDS, "blend_rows": psp.DEFAULT_CV_ROWS,
        "anchors": psp.DEFAULT_ANCHORS, "min_gain": None, "min_cchp_error": psp.DEFAULT_MIN_CCHP_ERROR,
        "min_fast_turns": psp.DEFAULT_MIN_FAST_TURNS, "fast_turn_rad_s": psp.FAST_TURN_RAD_S,
        "feature_dim": FEATURE_DIM + PATH_SHAPE_DIM, "commit": [psp.COMMIT_SHARE, psp.COMMIT_LOW, psp.COMMIT_HIGH],
        "match": [psp.MATCH_SHARE, psp.MATCH_VELOCITY_WEIGHT, psp.MATCH_TAU], "match_max_steps": psp.MATCH_MAX_STEPS,
        "features": card["path_shape_read"]["features"]}
    wide, inner = load_policy(models / "cchp_path_shape.pt"), load_policy(models / "cchp_default.pt")
    from rtcohand_drake.learning.command_hold import hold_settings

    assert hold_settings(wide) is None and psp.DEFAULT_HOLD[4] == 0.0  # no command hold asked for (not shipped)
    assert (wide.kernel_blend, wide.kernel_bandwidth, wide.kernel_lambda, wide.blend_folds, wide.blend_rows) == (
        psp.DEFAULT_BLEND, psp.DEFAULT_BANDWIDTH, psp.DEFAULT_LAMBDA, psp.DEFAULT_CV_FOLDS, psp.DEFAULT_CV_ROWS)
    assert (wide.kernel_anchors, wide.min_gain, wide.min_cchp_error) == (
        psp.DEFAULT_ANCHORS, psp.DEFAULT_MIN_GAIN, psp.DEFAULT_MIN_CCHP_ERROR) == (1536, float("-inf"), 0.5)
    assert (wide.min_fast_turns, wide.fast_turn_rad_s) == (psp.DEFAULT_MIN_FAST_TURNS, psp.FAST_TURN_RAD_S) == (0.1, 2.0)
    assert (wide.commit_share, wide.commit_low, wide.commit_high) == (0.5, 0.2, 0.6) == (
        psp.DEFAULT_COMMIT_SHARE, psp.COMMIT_LOW, psp.COMMIT_HIGH)
    assert (wide.match_share, wide.match_velocity_weight, wide.match_tau) == (0.25, 50.0, 0.05) == (
        psp.DEFAULT_MATCH_SHARE, psp.MATCH_VELOCITY_WEIGHT, psp.MATCH_TAU)
    assert int(wide.hidden_size) == int(inner.hidden_size) + 6 + psp.MATCH_MAX_STEPS
    rng = np.random.default_rng(5)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(_pieces(rng, [25, 18])))
    keys, values, z_mu, z_sigma = wide.encode_context(x_c, y_c, mask)
    inner_keys, inner_values, inner_mu, inner_sigma = inner.encode_context(x_c[:, :, :FEATURE_DIM].contiguous(), y_c, mask)
    assert torch.equal(wide._inner_keys(keys), inner_keys) and torch.equal(values, inner_values)
    assert torch.equal(z_mu, inner_mu) and torch.equal(z_sigma, inner_sigma)


def test_the_shipped_path_shape_file_is_what_the_builder_writes_today(tmp_path):
    """Rebuilt from models/cchp_default.pt by today's code, the file encodes and steps as the shipped one."""
    import pathlib

    from rtcohand_drake.learning import path_shape_policy as psp

    models = pathlib.Path(__file__).resolve().parents[1] / "models"
    shipped = load_policy(models / "cchp_path_shape.pt")
    rebuilt = load_policy(build_path_shape_policy(models / "cchp_default.pt", tmp_path / "rebuilt.pt",
                                                  min_gain=psp.DEFAULT_MIN_GAIN))
    rng = np.random.default_rng(6)
    context, (target, _) = _pieces(rng, [25, 18, 20, 16, 22]), _pieces(rng, [6])[0]
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    with torch.no_grad():
        encoded = [m.encode_context(x_c, y_c, mask) for m in (shipped, rebuilt)]
        for a, b in zip(*encoded):
            assert torch.equal(a, b)
        H = int(shipped.hidden_size)
        states = [(torch.zeros(H), torch.zeros(H), torch.zeros(6)) for _ in range(2)]
        for x in target:
            out = []
            for i, (m, enc) in enumerate(zip((shipped, rebuilt), encoded)):
                h, c, y = states[i]
                y, _, h, c, _ = m.step(torch.from_numpy(x), y, h, c, enc[0], enc[1], enc[2])
                states[i] = (h, c, y)
                out.append(y)
            assert torch.equal(out[0], out[1])


def test_a_long_context_is_read_from_anchors_spread_over_it(tmp_path):
    """A context longer than `--anchors` N: the kernel read is fitted on N of its steps spread evenly
    over it (step floor(i K / N)), checked against the kernel ridge on those steps written out in
    numpy; the attention is its equivalent kernel on them and 0 elsewhere; the keys and the step do
    not grow as K^2 (the keys hold the CCHP's, N^2 + O(N + K) more)."""
    from rtcohand_drake.learning import path_shape_policy as psp

    n = 16
    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "anchors.pt", blend=1.0, bandwidth=0.6,
                                   lam=0.4, folds=0, commit=(0.0, 0.2, 0.6), match=NO_MATCH, anchors=n)
    module = load_policy(path)
    rng = np.random.default_rng(12)
    context, (target, _) = _pieces(rng, [30, 22, 17]), _pieces(rng, [8])[0]
    k = sum(len(x) for x, _ in context)
    steps = np.floor(np.arange(n) * k / n).astype(int)
    x_all = np.concatenate([x for x, _ in context])
    y_all = np.concatenate([y for _, y in context])
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
    # The standardisation is the whole context's; the ridge is over the anchors.
    s_all = x_all[:, FEATURE_DIM:].astype(np.float64)
    mean, spread = s_all.mean(0), s_all.std(0) + 1e-6
    s = (s_all[steps] - mean) / spread
    d = np.sqrt(((s[:, None] - s[None]) ** 2).sum(-1))
    apart = np.sort(d[d > 0])
    width = 0.6 * apart[(len(apart) - 1) // 2]
    m_inv = np.linalg.inv(np.exp(-d ** 2 / (2 * width ** 2)) + 0.4 * np.eye(n))
    H = int(module.hidden_size)
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    with torch.no_grad():
        for x in target:
            q = (x[FEATURE_DIM:].astype(np.float64) - mean) / spread
            kern = np.exp(-((s - q) ** 2).sum(1) / (2 * width ** 2))
            y, _, h, c, attention = module.step(torch.from_numpy(x), y, h, c, keys, values, z_mu)
            assert np.allclose(y.numpy(), kern @ m_inv @ y_all[steps], atol=2e-5)
            expected = np.zeros(k)
            expected[steps] = kern @ m_inv
            assert np.allclose(attention.numpy(), expected, atol=2e-5)
    inner_width = load_policy(tmp_path / "inner.pt").encode_context(x_c[:, :, :FEATURE_DIM].contiguous(), y_c,
                                                                   mask)[0].shape[1]
    own = n * (n + PATH_SHAPE_DIM + 8) + module.extra_size
    assert keys.shape == (k, inner_width + -(-own // k))
    with pytest.raises(InputError, match="anchors must be"):
        build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "bad.pt", anchors=1)


def _beside_the_cchp(wide, inner, context, encoded, target):
    """Steps a path-and-shape file (its `step` and `step_read`) and its inner CCHP (encoded on the context's
    36 motion features) over the same target, each fed its own mean; yields per step ((mean, std, read,
    attention) of the file, the same of the CCHP, its read and attention averaged over its heads)."""
    x_c, y_c, mask = context
    keys, values, z_mu = encoded
    inner_keys, inner_values, inner_z, _ = inner.encode_context(x_c[:, :, :FEATURE_DIM].contiguous(), y_c, mask)
    h, c, y = torch.zeros(int(wide.hidden_size)), torch.zeros(int(wide.hidden_size)), torch.zeros(6)
    hi, ci, yi = torch.zeros(int(inner.hidden_size)), torch.zeros(int(inner.hidden_size)), torch.zeros(6)
    with torch.no_grad():
        for x in target:
            x = torch.from_numpy(x)
            read = wide.step_read(x, y, h, c, keys, values, z_mu)[4]
            y, std, h, c, attention = wide.step(x, y, h, c, keys, values, z_mu)
            yi, std_i, hi, ci, read_i, _, query_i = inner.step_read(x[:FEATURE_DIM], yi, hi, ci, inner_keys,
                                                                    inner_values, inner_z)
            attention_i = inner.attention_of(query_i, inner_keys)
            attention_i = attention_i.mean(0) if attention_i.dim() == 2 else attention_i
            yield (y, std, read, attention), (yi, std_i, read_i.mean(0).view(1, 6), attention_i)


def test_the_kernel_read_is_used_only_for_a_person_it_reads_better(tmp_path):
    """`--min-gain G`: A as fitted when the blend removes at least G of the CCHP's squared error over the
    person's own clips (`blend_choice`; the share is checked against its definition above), else 0 and
    the file's output is the CCHP's. A person only the path-and-shape read fits gets it; a person whose
    labels the path and shape do not tell gets the CCHP."""
    from rtcohand_drake.learning import path_shape_policy as psp
    from rtcohand_drake.learning.export import read_model_card

    inner_path = _inner_policy(tmp_path)
    inner = load_policy(inner_path)
    rng = np.random.default_rng(7)
    told = _pieces(rng, [14, 9, 12, 11, 8])
    for x, y in told:  # labels that the path and shape tell, and the 36 motion features do not
        y[:] = np.tanh(x[:, FEATURE_DIM:FEATURE_DIM + 6] * 10.0) * 0.1
    untold = _pieces(rng, [14, 9, 12, 11, 8])  # labels of nothing in the features
    open_file = load_policy(build_path_shape_policy(inner_path, tmp_path / "open.pt", bandwidth=0.6, lam=0.01,
                                                    folds=3, commit=(0.0, 0.2, 0.6), match=NO_MATCH, min_gain=0.0,
                                                    min_fast_turns=0.0))
    choices = {}
    for name, context in (("told", told), ("untold", untold)):
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
        used, fitted, gain, cchp_error = (float(v) for v in
                                          open_file.blend_choice(open_file.encode_context(x_c, y_c, mask)[0]))
        assert used == fitted
        choices[name] = (fitted, gain, cchp_error)
    assert choices["told"][1] > 0.5 and choices["untold"][1] < choices["told"][1] - 0.3, choices
    gate = 0.5 * (choices["told"][1] + choices["untold"][1])
    gated = load_policy(build_path_shape_policy(inner_path, tmp_path / "gated.pt", bandwidth=0.6, lam=0.01,
                                                folds=3, commit=(0.0, 0.2, 0.6), match=NO_MATCH, min_gain=gate,
                                                min_fast_turns=0.0))
    target = _pieces(rng, [10])[0][0]
    for name, context in (("told", told), ("untold", untold)):
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
        keys, values, z_mu, _ = gated.encode_context(x_c, y_c, mask)
        used, fitted, gain, cchp_error = (float(v) for v in gated.blend_choice(keys))
        assert (fitted, gain, cchp_error) == pytest.approx(choices[name], abs=1e-6)
        assert used == (fitted if name == "told" else 0.0)
        if name == "untold":  # the CCHP alone, step by step
            for (y, *_), (yi, *_) in _beside_the_cchp(gated, inner, (x_c, y_c, mask), (keys, values, z_mu), target):
                assert torch.allclose(y, yi, atol=1e-7)
    # `--min-gain off`: no gain condition; the person the gate refused gets the fitted blend.
    off_path = build_path_shape_policy(inner_path, tmp_path / "off.pt", bandwidth=0.6, lam=0.01, folds=3,
                                       commit=(0.0, 0.2, 0.6), match=NO_MATCH, min_gain=psp.GAIN_CONDITION_OFF,
                                       min_fast_turns=0.0)
    off = load_policy(off_path)
    for name, context in (("told", told), ("untold", untold)):
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
        used, fitted, gain, cchp_error = (float(v) for v in off.blend_choice(off.encode_context(x_c, y_c, mask)[0]))
        assert (fitted, gain, cchp_error) == pytest.approx(choices[name], abs=1e-6)
        assert used == fitted > 0.0
    assert read_model_card(off_path)["path_shape_read"]["min_gain"] is None
    with pytest.raises(InputError, match="min_gain"):
        build_path_shape_policy(inner_path, tmp_path / "bad.pt", min_gain=1.0)
    with pytest.raises(InputError, match="min-gain"):
        psp.main(["--policy", str(inner_path), "--out", str(tmp_path / "bad.pt"), "--min-gain", "-0.1"])


GATE_TEST_SETTINGS = dict(bandwidth=0.6, lam=0.01, folds=3, commit=(0.0, 0.2, 0.6), match=NO_MATCH, min_cchp_error=0.0,
                          min_blend=0.0, min_fast_turns=0.0)


def _fast_turning_context(rng):
    """Five clips whose labels the path and shape tell and the 36 motion features do not, with the palm
    turning faster than 2 rad/s in about half of the moving steps; and that share."""
    from rtcohand_drake.learning.path_shape_policy import FAST_TURN_RAD_S

    context = _pieces(rng, [14, 9, 12, 11, 8])
    for x, y in context:
        y[:] = np.tanh(x[:, FEATURE_DIM:FEATURE_DIM + 6] * 10.0) * 0.1
        x[:, 3:6] = rng.uniform(-2.0, 2.0, (len(x), 3))  # the palm's turn: about half the steps over 2 rad/s
        x[::4, :FEATURE_DIM] = 0.0  # still steps, which the share leaves out
    motion = np.concatenate([x[:, :FEATURE_DIM] for x, _ in context])
    moving = np.abs(motion).sum(1) > 0
    fast_turns = float(np.mean(np.linalg.norm(motion[moving, 3:6], axis=1) > FAST_TURN_RAD_S))
    assert FAST_TURN_RAD_S == 2.0 and 0.2 < fast_turns < 0.8 and moving.mean() < 0.8
    return context, fast_turns


def test_the_kernel_read_steps_in_only_for_a_person_the_cchp_does_not_read(tmp_path):
    """`--min-cchp-error E`: A as fitted when the CCHP alone, cross-validated over the person's own clips,
    reads them with at least E of zero twist's squared error (`blend_choice`'s last entry, checked against
    its definition above); `--min-blend B`: A as fitted when it is at least B; `--min-fast-turns F`: when
    the palm turns faster than 2 rad/s in at least F of the context's moving steps. Else A = 0, and each
    step is the CCHP's own step exactly: mean, std, read (its heads' mean) and attention."""
    inner_path = _inner_policy(tmp_path)
    inner = load_policy(inner_path)
    rng = np.random.default_rng(11)
    context, fast_turns = _fast_turning_context(rng)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    settings = GATE_TEST_SETTINGS
    open_file = load_policy(build_path_shape_policy(inner_path, tmp_path / "open.pt", **settings))
    _, fitted, gain, cchp_error = (float(v) for v in open_file.blend_choice(open_file.encode_context(x_c, y_c, mask)[0]))
    assert fitted > 0.05 and cchp_error > 0.1
    assert float(open_file.fast_turn_share(x_c, mask)) == pytest.approx(fast_turns, abs=1e-9)
    target = _pieces(rng, [10])[0][0]
    gates = ((dict(min_cchp_error=cchp_error - 0.05), True), (dict(min_cchp_error=cchp_error + 0.05), False),
             (dict(min_cchp_error=cchp_error - 0.05, min_blend=fitted - 0.02), True),
             (dict(min_cchp_error=cchp_error - 0.05, min_blend=fitted + 0.02), False),
             (dict(min_cchp_error=cchp_error - 0.05, min_fast_turns=fast_turns - 0.02), True),
             (dict(min_cchp_error=cchp_error - 0.05, min_fast_turns=fast_turns + 0.02), False))
    for i, (gate, kernel_used) in enumerate(gates):
        gated = load_policy(build_path_shape_policy(inner_path, tmp_path / f"gated{i}.pt", **{**settings, **gate}))
        keys, values, z_mu, _ = gated.encode_context(x_c, y_c, mask)
        used, *rest = (float(v) for v in gated.blend_choice(keys))
        fitted_keys = gated.encode_context_fitted(x_c, y_c, mask)[0]
        used_fitted, *rest_fitted = (float(v) for v in gated.blend_choice(fitted_keys))
        assert rest_fitted == pytest.approx([fitted, gain, cchp_error], abs=1e-6) and used_fitted == used
        assert used == (fitted if kernel_used else 0.0) and keys.shape == fitted_keys.shape
        if "min_fast_turns" in gate and not kernel_used:
            # Turned away by the fast-turn gate: the kernel read is neither fitted nor cross-validated.
            assert rest == [pytest.approx(float(gated.kernel_blend)), -1.0, -1.0]
        else:
            assert torch.equal(keys, fitted_keys)
        differs = False
        for (y, std, read, attention), (yi, std_i, read_i, attention_i) in _beside_the_cchp(
                gated, inner, (x_c, y_c, mask), (keys, values, z_mu), target):
            if kernel_used:
                differs = differs or not torch.equal(y, yi)
            else:
                assert (torch.equal(y, yi) and torch.equal(std, std_i) and torch.equal(read, read_i)
                        and torch.equal(attention, attention_i))
        assert differs == kernel_used
    with pytest.raises(InputError, match="min_cchp_error"):
        build_path_shape_policy(inner_path, tmp_path / "bad.pt", min_cchp_error=-0.1)
    with pytest.raises(InputError, match="min_blend"):
        build_path_shape_policy(inner_path, tmp_path / "bad.pt", min_blend=-0.5)
    with pytest.raises(InputError, match="min_fast_turns"):
        build_path_shape_policy(inner_path, tmp_path / "bad.pt", min_fast_turns=1.5)


def _box_twists(model, pieces, features, keypoints):
    """The policy box's twist, period by period, for the steps `features` (the skeleton `keypoints`
    held, where given); and the box."""
    from rtcohand_drake.interfaces import GESTURE_FEATURES, POLICY_MEAN
    from rtcohand_drake.systems.policy import CchpPolicy

    box = CchpPolicy(model, pieces, 10.0, seed=2, rest_release=False, command_hold=False)
    simulator = Simulator(box)
    ctx = simulator.get_mutable_context()
    out = []
    for k, x in enumerate(features):  # each period's features, then the box's update at k / 10 s
        box.GetInputPort(GESTURE_FEATURES).FixValue(ctx, x)
        if keypoints is not None:
            box.GetInputPort(KEYPOINTS).FixValue(ctx, keypoints)
        simulator.AdvanceTo(k * 0.1 + 0.05)
        out.append(box.GetOutputPort(POLICY_MEAN).Eval(ctx).copy())
    return np.array(out), box


def test_the_box_of_a_person_the_file_reads_with_the_cchp_alone_is_the_cchp_box_and_leaves_the_skeleton(tmp_path):
    """A person the fast-turn gate turns away: the policy box with the wide file gives, period by period,
    the twist of the box with its CCHP file alone, and never reads its keypoints port (left unconnected
    here, which Drake refuses to evaluate); a person the gate lets through gets the kernel read, from the
    skeleton."""
    from rtcohand_drake.interfaces import GESTURE_FEATURES, POLICY_MEAN
    from rtcohand_drake.systems.policy import CchpPolicy

    inner_path = _inner_policy(tmp_path)
    rng = np.random.default_rng(11)
    context, fast_turns = _fast_turning_context(rng)
    features = _pieces(rng, [12])[0][0][:, :FEATURE_DIM]
    twists = lambda model, pieces, keypoints: _box_twists(model, pieces, features, keypoints)  # noqa: E731

    narrow = [(x[:, :FEATURE_DIM], y) for x, y in context]
    alone, _ = twists(inner_path, narrow, None)
    turned_away = build_path_shape_policy(inner_path, tmp_path / "away.pt",
                                          **{**GATE_TEST_SETTINGS, "min_fast_turns": fast_turns + 0.02})
    wide, box = twists(turned_away, context, None)
    assert box.HasInputPort(KEYPOINTS) and np.abs(alone).max() > 1e-3
    np.testing.assert_array_equal(wide, alone)
    let_through = build_path_shape_policy(inner_path, tmp_path / "through.pt", **GATE_TEST_SETTINGS)
    with pytest.raises(RuntimeError, match="keypoints"):
        twists(let_through, context, None)
    skeleton = rng.normal(0.0, 0.05, 63)
    assert not np.allclose(twists(let_through, context, skeleton)[0], alone, atol=1e-4)


def test_the_box_takes_the_36_features_alone_from_a_person_the_fast_turn_gate_turns_away(tmp_path):
    """`turned_away_by_fast_turns` asks the file's own gate from the 36 features: for a person it turns
    away, the box built from those alone gives, period by period, the twist of the box built from the full
    features (so a run need not build the path and shape); a person it lets through must bring them, and a
    file without the gate, or a context of one clip (whose blend is not cross-validated), is never
    turned away."""
    from rtcohand_drake.learning.path_shape_policy import turned_away_by_fast_turns

    inner_path = _inner_policy(tmp_path)
    rng = np.random.default_rng(11)
    context, fast_turns = _fast_turning_context(rng)
    features = _pieces(rng, [12])[0][0][:, :FEATURE_DIM]
    narrow = [(x[:, :FEATURE_DIM].copy(), y) for x, y in context]
    away = build_path_shape_policy(inner_path, tmp_path / "away.pt",
                                   **{**GATE_TEST_SETTINGS, "min_fast_turns": fast_turns + 0.02})
    through = build_path_shape_policy(inner_path, tmp_path / "through.pt",
                                      **{**GATE_TEST_SETTINGS, "min_fast_turns": fast_turns - 0.02})
    x_c, _, mask = pack_context(narrow)
    assert turned_away_by_fast_turns(load_policy(away), x_c, mask)
    assert not turned_away_by_fast_turns(load_policy(through), x_c, mask)
    assert not turned_away_by_fast_turns(load_policy(inner_path), x_c, mask)
    one_clip, _, one_mask = pack_context(narrow[:1])
    assert not turned_away_by_fast_turns(load_policy(away), one_clip, one_mask)
    from_narrow, box = _box_twists(away, narrow, features, None)
    from_wide, _ = _box_twists(away, context, features, None)
    assert box.HasInputPort(KEYPOINTS) and np.abs(from_wide).max() > 1e-3
    np.testing.assert_array_equal(from_narrow, from_wide)
    with pytest.raises(InputError, match="reads 351 features per step, the context pieces have \\[36\\]"):
        _box_twists(through, narrow, features, None)


def test_a_file_wrapped_around_the_path_and_shape_file_reads_the_skeleton_whatever_its_own_blend(tmp_path):
    """A ridge blend built over a path-and-shape file (`ridge_blend_policy`, the three reads in one file)
    gives its ridge's blend in `blend_choice`, not the kernel read's A: with the ridge off (B = 0) and the
    kernel read on, the box still needs the skeleton, and is never offered the 36 features alone."""
    from rtcohand_drake.learning.path_shape_policy import turned_away_by_fast_turns
    from rtcohand_drake.learning.ridge_blend_policy import build_ridge_blend_policy

    inner_path = _inner_policy(tmp_path)
    rng = np.random.default_rng(11)
    context, _ = _fast_turning_context(rng)
    features = _pieces(rng, [12])[0][0][:, :FEATURE_DIM]
    path_shape = build_path_shape_policy(inner_path, tmp_path / "through.pt", **GATE_TEST_SETTINGS)
    stacked = load_policy(build_ridge_blend_policy(path_shape, tmp_path / "stacked.pt", min_gain=0.99))
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys = stacked.encode_context(x_c, y_c, mask)[0]
    inner_keys = load_policy(path_shape).encode_context(x_c, y_c, mask)[0]
    assert float(stacked.blend_choice(keys)[0]) == 0.0  # the ridge off
    assert float(load_policy(path_shape).blend_choice(inner_keys)[0]) > 0.0  # the kernel read on
    with pytest.raises(RuntimeError, match="keypoints"):
        _box_twists(stacked, context, features, None)
    narrow = [(x[:, :FEATURE_DIM].copy(), y) for x, y in context]
    assert not turned_away_by_fast_turns(stacked, *pack_context(narrow)[::2])


def test_a_caller_of_the_36_features_alone_gets_the_cchp_exactly(tmp_path):
    """A file that reads the path and shape is still a policy of the paper's 36 features (the exported
    policy's contract): given a context and steps of those alone, it is read by the CCHP alone, exactly,
    even where the person's wide context would give the kernel read a share; any other width is refused."""
    inner_path = _inner_policy(tmp_path)
    inner = load_policy(inner_path)
    wide = load_policy(build_path_shape_policy(inner_path, tmp_path / "open.pt", bandwidth=0.6, lam=0.01, folds=3,
                                               match=NO_MATCH, min_cchp_error=0.0, min_fast_turns=0.0))
    rng = np.random.default_rng(11)
    context = _pieces(rng, [14, 9, 12, 11, 8])
    for x, y in context:  # labels that the path and shape tell
        y[:] = np.tanh(x[:, FEATURE_DIM:FEATURE_DIM + 6] * 10.0) * 0.1
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    assert float(wide.blend_choice(wide.encode_context(x_c, y_c, mask)[0])[0]) > 0.05  # wide: the kernel read
    narrow = x_c[:, :, :FEATURE_DIM].contiguous()
    keys, values, z_mu, z_sigma = wide.encode_context(narrow, y_c, mask)
    assert float(wide.blend_choice(keys)[0]) == 0.0
    inner_keys, inner_values, inner_mu, inner_sigma = inner.encode_context(narrow, y_c, mask)
    assert torch.equal(wide._inner_keys(keys), inner_keys) and torch.equal(values, inner_values)
    assert torch.equal(z_mu, inner_mu) and torch.equal(z_sigma, inner_sigma)
    target = [x[:, :FEATURE_DIM].copy() for x, _ in _pieces(rng, [10])]
    steps = 0
    for (y, std, read, attention), (yi, std_i, read_i, attention_i) in _beside_the_cchp(
            wide, inner, (narrow, y_c, mask), (keys, values, z_mu), target[0]):
        assert (torch.equal(y, yi) and torch.equal(std, std_i) and torch.equal(read, read_i)
                and torch.equal(attention, attention_i))
        steps += 1
    assert steps == 10
    with pytest.raises(Exception, match="x_c must be"):
        wide.encode_context(x_c[:, :, :40].contiguous(), y_c, mask)
    h = torch.zeros(int(wide.hidden_size))
    with pytest.raises(Exception, match="x_t must have"):
        wide.step(torch.zeros(40), torch.zeros(6), h, h, keys, values, z_mu)


def test_the_reading_check_says_which_read_a_person_gets_and_why(tmp_path):
    """`context_reading.read_choice`: the kernel read and its blend where both gates let it in; the CCHP
    alone otherwise, with the figures that decided, and how to get the kernel read for a real hand
    tracked so smoothly that its palm never turns fast."""
    from rtcohand_drake.analysis.context_reading import LabelledClip, read_choice

    inner_path = _inner_policy(tmp_path)
    rng = np.random.default_rng(11)
    context = _pieces(rng, [14, 9, 12, 11, 8])
    for x, y in context:  # labels that the path and shape tell; the palm turns fast in about half the steps
        y[:] = np.tanh(x[:, FEATURE_DIM:FEATURE_DIM + 6] * 10.0) * 0.1
        x[:, 3:6] = rng.uniform(-2.0, 2.0, (len(x), 3))
    clips = [LabelledClip(f"c{i}", x, y, (0,)) for i, (x, y) in enumerate(context)]
    settings = dict(bandwidth=0.6, lam=0.01, folds=3, commit=(0.0, 0.2, 0.6), match=NO_MATCH, min_cchp_error=0.0)
    opened = load_policy(build_path_shape_policy(inner_path, tmp_path / "open.pt", **settings))
    line = read_choice(opened, clips)
    assert line.startswith("read: the CCHP and the kernel read of the hand's path and shape, blended ")
    assert "faster than 2 rad/s in " in line and "(from 10%)" in line and "--min-fast-turns 0" not in line
    smooth = load_policy(build_path_shape_policy(inner_path, tmp_path / "smooth.pt", **settings, min_fast_turns=0.9))
    line = read_choice(smooth, clips)
    assert line.startswith("read: the CCHP alone: ") and "(from 90%)" in line and "--min-fast-turns 0" in line
    assert read_choice(load_policy(inner_path), clips) is None  # a CCHP file: nothing to choose


def test_context_reading_checks_a_persons_clips_with_the_path_shape_file(tmp_path, person_file, capsys):
    """The reading check gives the wide file the path and shape, the ridge and nearest neighbours the 36
    velocities, and adds the kernel read of the path and shape as a third reference."""
    from rtcohand_drake.analysis.context_reading import main

    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "wide.pt")
    clips = read_dataset(person_file)
    small = tmp_path / "eight_clips.h5"
    write_dataset(small, [c for c in clips if c.user == clips[0].user][:8])
    assert main(["--context-file", str(small), "--model", str(path), "--folds", "3"]) == 0
    out = capsys.readouterr().out
    assert "policy wide.pt" in out and "held-out squared error over the played clips" in out
    assert "kernel read of the path and shape (bandwidth 0.5, lambda 0.3)" in out  # the third reference


@pytest.mark.parametrize("source", ["replay", "synthetic"])
def test_the_run_command_gives_the_path_shape_file_its_wider_context(tmp_path, person_file, source):
    """`run --model` with the file for real hands: the replayed person's other clips, or the built-in
    person's own clips, become its context with the path and shape; the run ends normally."""
    import subprocess
    import sys

    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "wide.pt")
    clip = read_dataset(person_file)[0]
    args = (["--gesture-source", "replay", "--gesture-file", str(person_file), "--clip", clip.name]
            if source == "replay" else ["--gesture-source", "synthetic", "--duration", "3"])
    run = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--no-meshcat", "--realtime-rate", "0",
                          "--model", str(path), "--log", str(tmp_path / "run.h5"), *args],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert (tmp_path / "run.h5").is_file() and "simulated in" in run.stdout


def test_an_encoder_learned_across_people_is_what_the_kernel_reads(tmp_path, person_file):
    """`hand_encoder` learns from a file's people; the policy file built with it reads the kernel over
    the encoder's embedding, exactly as the same read written out in numpy over that embedding."""
    from rtcohand_drake.learning import hand_encoder

    people = hand_encoder.people_of([person_file])
    assert len(people) == 2 and people[0][0][0].shape[1] == PATH_SHAPE_DIM
    encoder, summary = hand_encoder.train_encoder(people, iterations=3, seed=0, max_clips=6, progress=False)
    assert summary["iterations"] == 3 and np.isfinite(summary["final_loss"])
    enc_path = hand_encoder.save_encoder(encoder, tmp_path / "encoder.pt", {"trained_on": [person_file.name]})
    scripted, card = hand_encoder.load_encoder(enc_path)
    assert card["kind"] == "hand_encoder" and card["embed_dim"] == hand_encoder.EMBED_DIM

    def embed(s):
        with torch.no_grad():
            return scripted(torch.from_numpy(np.asarray(s, np.float32))).numpy()

    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "wide.pt", blend=1.0, bandwidth=0.6, lam=0.4,
                                   folds=0, encoder=enc_path, commit=(0.0, 0.2, 0.6), match=NO_MATCH)
    module = load_policy(path)
    assert int(module.feature_dim) == FEATURE_DIM + PATH_SHAPE_DIM
    rng = np.random.default_rng(2)
    context, (target, _) = _pieces(rng, [20, 15]), _pieces(rng, [8])[0]
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
    expected, raw = _kernel_read(context, target, 0.6, 0.4, embed), _kernel_read(context, target, 0.6, 0.4)
    assert np.abs(expected - raw).max() > 1e-3  # the embedding changes the read
    H = int(module.hidden_size)
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    with torch.no_grad():
        for t, x in enumerate(target):
            y, _, h, c, _ = module.step(torch.from_numpy(x), y, h, c, keys, values, z_mu)
            # 1 %: torch.cdist's rounding leaves a few of the diagonal's zero distances at 1e-7, which the
            # module's median distance counts; it moves the width by a few parts in a thousand here.
            assert np.allclose(y.numpy(), expected[t], rtol=1e-2, atol=2e-4), (t, y.numpy(), expected[t])
    from rtcohand_drake.learning.export import read_model_card

    assert read_model_card(path)["path_shape_read"]["encoder"]["trained_on"] == [person_file.name]


def test_the_encoder_learns_a_read_that_tells_motions_apart():
    """People whose six motions differ only in where the hand goes, each clip made by a hand of its own
    shape: the raw features' distance is mostly the shape. Training lowers the kernel read's error on
    held-out clips of the people it learned from."""
    from rtcohand_drake.data.hand_features import PATH_SHAPE_LAGS_S
    from rtcohand_drake.learning import hand_encoder

    rng = np.random.default_rng(0)

    def clip(d, sign):  # the path and shape (as PathShapeStream gives it) of a hand that starts to slide at step 4
        shape = rng.normal(scale=0.04, size=(21, 3))
        x = np.zeros((12, PATH_SHAPE_DIM), np.float32)
        for t in range(12):
            for i, lag in enumerate(PATH_SHAPE_LAGS_S):
                moved = 0.15 * sign * min(lag, max(0.0, (t - 4) / 10.0))  # how far it went in the last `lag` s
                x[t, 63 * i:63 * (i + 1)] = (shape - moved * np.eye(3)[d]).ravel()
        y = np.zeros((12, 6))
        y[5:, d] = 0.12 * sign
        return x + rng.normal(scale=0.002, size=x.shape).astype(np.float32), y

    people = [[clip(d, sign) for _ in range(3) for d in range(3) for sign in (1, -1)] for _ in range(3)]

    def held_out_error(encoder):
        errors = []
        for person in people:
            ctx, tgt = person[:12], person[12:]
            with torch.no_grad():
                zc = encoder(torch.from_numpy(np.concatenate([x for x, _ in ctx]))).double()
                zt = encoder(torch.from_numpy(np.concatenate([x for x, _ in tgt]))).double()
                pred = hand_encoder.kernel_read(zc, torch.from_numpy(np.concatenate([y for _, y in ctx])), zt, 0.5, 0.3)
            y = np.concatenate([y for _, y in tgt])
            errors.append(np.mean((pred.numpy() - y) ** 2) / np.mean(y ** 2))
        return float(np.mean(errors))

    untrained, _ = hand_encoder.train_encoder(people, iterations=1, seed=0, lr=0.0, progress=False)
    before = held_out_error(untrained)
    trained, summary = hand_encoder.train_encoder(people, iterations=150, seed=0, progress=False)
    assert summary["iterations"] == 150
    after = held_out_error(trained)
    assert after < 0.3 * before, (after, before)  # measured: 0.05 against 0.73


def test_bad_encoder_files_and_data_are_one_line_errors(tmp_path, person_file):
    from rtcohand_drake.learning import hand_encoder

    inner = _inner_policy(tmp_path)
    with pytest.raises(InputError, match="no such encoder file"):
        build_path_shape_policy(inner, tmp_path / "wide.pt", encoder=tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not an encoder file"):
        hand_encoder.load_encoder(tmp_path / "junk.pt")
    with pytest.raises(InputError, match="no encoder card"):
        hand_encoder.load_encoder(inner)  # a policy file is not an encoder
    with pytest.raises(InputError, match="iterations >= 1"):
        hand_encoder.train_encoder([], iterations=5)
    unlabelled = tmp_path / "unlabelled.h5"
    import dataclasses

    write_dataset(unlabelled, [dataclasses.replace(c, object_velocity=None) for c in read_dataset(person_file)[:3]])
    with pytest.raises(InputError, match="no labelled clips"):
        hand_encoder.people_of([unlabelled])


def test_the_encoder_commands_build_a_policy_file_and_reject_a_bad_file_in_one_line(tmp_path, person_file):
    import subprocess
    import sys

    def run(module, *args):
        return subprocess.run([sys.executable, "-m", module, *map(str, args)], capture_output=True, text=True,
                              timeout=300)

    encoder = tmp_path / "encoder.pt"
    proc = run("rtcohand_drake.learning.hand_encoder", "--data", person_file, "--out", encoder, "--iterations", 2)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "learning from 2 people of 1 file(s)" in proc.stdout and encoder.is_file()
    wide = tmp_path / "wide.pt"
    proc = run("rtcohand_drake.learning.path_shape_policy", "--policy", _inner_policy(tmp_path), "--out", wide,
               "--encoder", encoder)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert int(load_policy(wide).shape_dim) == 64
    broken = tmp_path / "broken.h5"
    broken.write_bytes(person_file.read_bytes()[:5000])
    proc = run("rtcohand_drake.learning.hand_encoder", "--data", broken, "--out", tmp_path / "no.pt")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and str(broken) in lines[0], proc.stderr[-2000:]
    assert not (tmp_path / "no.pt").exists()


def test_a_committed_read_is_the_kernel_reads_dominant_command_at_its_size(tmp_path):
    """With --commit SHARE LOW HIGH, SHARE of the kernel read is replaced by its dominant command (the axis
    largest as a share of the context's largest label on it), at full size from HIGH of that size, none
    below LOW: checked against the same written out in numpy, step by step."""
    share, low, high = 0.5, 0.2, 0.6
    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "wide.pt", blend=1.0, bandwidth=0.6, lam=0.4,
                                   folds=0, commit=(share, low, high), match=NO_MATCH)
    module = load_policy(path)
    rng = np.random.default_rng(3)
    context, (target, _) = _pieces(rng, [30, 22, 17]), _pieces(rng, [12])[0]
    for i, (_, y) in enumerate(context):  # labels of a command's size on some axes, none on the last
        y[:] = 0.0
        y[5:, i % 3] = (0.12, -0.12, 0.3)[i]
        y[2:4, 3] = 0.6
    sizes = np.array([0.12, 0.12, 0.3, 0.6, 0.0, 0.0])
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
    kernel = _kernel_read(context, target, 0.6, 0.4)
    H = int(module.hidden_size)
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    committed_steps = 0
    with torch.no_grad():
        for t, x in enumerate(target):
            y, _, h, c, _ = module.step(torch.from_numpy(x), y, h, c, keys, values, z_mu)
            r = kernel[t]
            s = np.divide(r, sizes, out=np.zeros(6), where=sizes > 0)
            axis = int(np.argmax(np.abs(s)))
            sure = np.clip((abs(s[axis]) - low) / (high - low), 0.0, 1.0)
            command = np.zeros(6)
            command[axis] = sure * np.sign(s[axis]) * sizes[axis]
            committed_steps += sure > 0
            assert np.allclose(y.numpy(), share * command + (1 - share) * r, rtol=1e-2, atol=2e-4), (t, y, r)
    assert committed_steps >= 3  # the check saw the commitment act
    from rtcohand_drake.learning.export import read_model_card

    assert read_model_card(path)["path_shape_read"]["commit"] == [share, low, high]
    with pytest.raises(InputError, match="commit needs"):
        build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "bad.pt", commit=(0.5, 0.6, 0.2))


def _time_warp_read(context, stream, velocity_weight, tau):
    """The stroke matched against each context clip, written out in numpy from its definition: each
    frame is the shape about the centre now (63) and the centre's velocity over 0.4 s (3), standardised
    by the context's frames; a match starts at a clip's first step at any step of the stream and
    advances by (1, 1), (1, 0) or (1, 2), the one of least mean cost per matched step; each clip's best
    step (least mean cost) gives its labels, weighted by exp(-(its cost - the best clip's) / tau)."""
    def frames(x):
        p = x[:, FEATURE_DIM:].astype(np.float64)
        return np.hstack([p[:, :63], -p[:, 63:126].reshape(-1, 21, 3).mean(1) / 0.4])

    f_all = np.concatenate([frames(x) for x, _ in context])
    mean, spread = f_all.mean(0), f_all.std(0) + 1e-6
    weight = np.r_[np.ones(63), np.full(3, velocity_weight)]
    weight /= weight.sum()
    clips = [((frames(x) - mean) / spread, y.astype(np.float64)) for x, y in context]
    paths = [[None] * len(f) for f, _ in clips]  # (cost, length) of the best match ending at each step
    reads = []
    for q in (frames(stream) - mean) / spread:
        best = []
        for k, (f, y) in enumerate(clips):
            d = ((f - q) ** 2) @ weight
            before = paths[k]
            now = []
            for j in range(len(f)):
                options = [(0.0, 0)] if j == 0 else []  # a fresh start at the clip's first step
                for jj in (j - 1, j, j - 2):
                    if 0 <= jj and before[jj] is not None:
                        options.append(before[jj])
                if not options:  # no match reaches this step yet
                    now.append(None)
                    continue
                cost, length = min(options, key=lambda o: (o[0] + d[j]) / (o[1] + 1))
                now.append((cost + d[j], length + 1))
            paths[k] = now
            mean_cost = [np.inf if o is None else o[0] / o[1] for o in now]
            j = int(np.argmin(mean_cost))
            best.append((mean_cost[j], y[j]))
        costs = np.array([c for c, _ in best])
        w = np.exp(-(costs - costs.min()) / tau)
        reads.append((w[:, None] * np.array([y for _, y in best])).sum(0) / w.sum())
    return np.array(reads)


def test_the_stroke_matched_by_a_time_warp_reads_as_its_definition(tmp_path):
    """With --match SHARE W TAU, SHARE of the kernel read is replaced by the stroke's time-warped match
    against each context clip: with SHARE 1 and A = 1 the file reads the match alone, checked step by
    step against the same written out in numpy; its state rides in h and c after the CCHP's, a new
    stream (h = c = 0) starts afresh, and a context longer than the state holds is read by the kernel
    alone."""
    from rtcohand_drake.learning import path_shape_policy as psp

    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "match.pt", blend=1.0, folds=0,
                                   commit=(0.0, 0.2, 0.6), match=(1.0, 20.0, 0.1))
    module = load_policy(path)
    base = int(load_policy(tmp_path / "inner.pt").hidden_size) + 6  # the CCHP's state and its own mean
    rng = np.random.default_rng(11)
    context = _pieces(rng, [9, 14, 11, 7])
    stream = np.concatenate([context[1][0][:6], context[3][0][2:], _pieces(rng, [4])[0][0]])
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
    expected = _time_warp_read(context, stream, 20.0, 0.1)
    H = int(module.hidden_size)
    assert H == base + psp.MATCH_MAX_STEPS
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    with torch.no_grad():
        for t, x in enumerate(stream):
            y, _, h, c, _ = module.step(torch.from_numpy(x), y, h, c, keys, values, z_mu)
            assert np.allclose(y.numpy(), expected[t], atol=1e-5), (t, y.numpy(), expected[t])
    assert np.abs(expected).max() > 0.05 and len({tuple(np.round(r, 6)) for r in expected}) > 5
    assert float(c[base:].max()) > 1 and float(c[base + 41:].abs().max()) == 0.0  # lengths of the 41 steps only
    # A context longer than the state holds: the kernel read alone (as the file without the match).
    alone = load_policy(build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "alone.pt", blend=1.0, folds=0,
                                                commit=(0.0, 0.2, 0.6), match=NO_MATCH))
    long_context = _pieces(rng, [psp.MATCH_MAX_STEPS // 2 + 1, psp.MATCH_MAX_STEPS // 2])
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(long_context))
    with torch.no_grad():
        keys, values, z_mu, _ = module.encode_context(x_c, y_c, mask)
        keys_a, values_a, z_a, _ = alone.encode_context(x_c, y_c, mask)
        y, _, h, c, _ = module.step(torch.from_numpy(stream[0]), torch.zeros(6), torch.zeros(H), torch.zeros(H),
                                    keys, values, z_mu)
        y_a, _, _, _, _ = alone.step(torch.from_numpy(stream[0]), torch.zeros(6), torch.zeros(H - psp.MATCH_MAX_STEPS),
                                     torch.zeros(H - psp.MATCH_MAX_STEPS), keys_a, values_a, z_a)
    assert torch.allclose(y, y_a, atol=1e-6) and float(c[base:].abs().max()) == 0.0
    with pytest.raises(InputError, match="match needs"):
        build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "bad.pt", match=(0.5, 50.0, 0.0))


def test_reads_path_shape_tells_a_file_that_needs_the_path_and_shape_in_its_context():
    """Callers that build a context for a policy file ask this (`learning.policy_file.reads_path_shape`)."""
    import pathlib

    from rtcohand_drake.learning.policy_file import reads_path_shape

    models = pathlib.Path(__file__).resolve().parents[1] / "models"
    assert reads_path_shape(models / "cchp_path_shape.pt") and not reads_path_shape(models / "cchp_default.pt")
    assert reads_path_shape(load_policy(models / "cchp_path_shape.pt"))
    assert not reads_path_shape(str(models / "cchp_default.pt"))
