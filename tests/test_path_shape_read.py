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


def _kernel_read(context, query, bandwidth, lam):
    """Gaussian-kernel ridge over the standardised path-and-shape columns, written out in numpy."""
    s = np.concatenate([x[:, FEATURE_DIM:] for x, _ in context]).astype(np.float64)
    y = np.concatenate([l for _, l in context]).astype(np.float64)
    mean, spread = s.mean(0), s.std(0) + 1e-6
    s = (s - mean) / spread
    d = np.sqrt(((s[:, None] - s[None]) ** 2).sum(-1))
    apart = np.sort(d[d > 0])
    width = bandwidth * apart[(len(apart) - 1) // 2]  # the lower median, as torch.median
    weights = np.linalg.solve(np.exp(-d ** 2 / (2 * width ** 2)) + lam * np.eye(len(s)), y)
    q = (query[:, FEATURE_DIM:].astype(np.float64) - mean) / spread
    near = np.sqrt(((q[:, None] - s[None]) ** 2).sum(-1))
    return np.exp(-near ** 2 / (2 * width ** 2)) @ weights


def test_policy_file_blends_the_cchp_with_a_kernel_read_of_the_context(tmp_path):
    inner_path = _inner_policy(tmp_path)
    path = build_path_shape_policy(inner_path, tmp_path / "wide.pt", blend=0.7, bandwidth=0.6, lam=0.4, folds=0)
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
        module.encode_context(x_c[:, :, :FEATURE_DIM].contiguous(), y_c, mask)


def test_cross_validated_blend_matches_refitting_without_each_fold(tmp_path):
    """With --folds, A is the least-squares blend of the two reads over the person's own clips, each
    read with the other folds' clips as context: here the kernel read is refitted from scratch."""
    inner_path = _inner_policy(tmp_path)
    path = build_path_shape_policy(inner_path, tmp_path / "cv.pt", bandwidth=0.6, lam=0.01, folds=3)
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
    num = den = 0.0
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
                    num += (kernel[t] - cchp) @ (y_all[span[t]] - cchp)
                    den += (kernel[t] - cchp) @ (kernel[t] - cchp)
    expected = float(np.clip(num / den, 0.0, 1.0))
    assert 0.05 < expected < 0.999  # a blend, not a bound
    assert float(module._blend(keys)) == pytest.approx(expected, abs=2e-4)


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
    twist is the module's, stepped offline on the clip's features."""
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.data.hand_features import resample
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.replay import ReplayGestureSource
    from rtcohand_drake.systems.policy import CchpPolicy

    path = build_path_shape_policy(_inner_policy(tmp_path), tmp_path / "wide.pt")
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
    H = int(module.hidden_size)
    h, c, y, z = torch.zeros(H), torch.zeros(H), torch.zeros(6), torch.from_numpy(policy.sample_z(0).astype(np.float32))
    # The replayed skeleton, as the box sees it, through the stream (the file's own path-and-shape
    # features interpolate across the simulated camera's dropped frames differently).
    stream = PathShapeStream(10.0)
    shape = np.array([stream.update(s)[0] for s in skeleton])
    offline = []
    with torch.no_grad():
        for x in np.hstack([clip.features[:, :FEATURE_DIM], shape]).astype(np.float32):
            y, _, h, c, _ = module.step(torch.from_numpy(x), y, h, c, keys, values, z)
            offline.append(y.numpy().copy())
    offline = np.array(offline)
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
        "feature_dim": FEATURE_DIM + PATH_SHAPE_DIM,
        "features": card["path_shape_read"]["features"]}
    wide, inner = load_policy(models / "cchp_path_shape.pt"), load_policy(models / "cchp_default.pt")
    assert (wide.kernel_blend, wide.kernel_bandwidth, wide.kernel_lambda, wide.blend_folds, wide.blend_rows) == (
        psp.DEFAULT_BLEND, psp.DEFAULT_BANDWIDTH, psp.DEFAULT_LAMBDA, psp.DEFAULT_CV_FOLDS, psp.DEFAULT_CV_ROWS)
    rng = np.random.default_rng(5)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(_pieces(rng, [25, 18])))
    keys, values, z_mu, z_sigma = wide.encode_context(x_c, y_c, mask)
    inner_keys, inner_values, inner_mu, inner_sigma = inner.encode_context(x_c[:, :, :FEATURE_DIM].contiguous(), y_c, mask)
    assert torch.equal(keys[:, -inner_keys.shape[1]:], inner_keys) and torch.equal(values, inner_values)
    assert torch.equal(z_mu, inner_mu) and torch.equal(z_sigma, inner_sigma)


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
