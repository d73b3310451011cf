"""The exported TorchScript policy (docs/interfaces.md, the exported policy) against the Python model."""

import pathlib
import subprocess
import sys

import numpy as np
import pytest
import torch

from rtcohand_drake.learning.export import load_policy, script_policy
from rtcohand_drake.learning.batching import collate, collate_context
from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig
from rtcohand_drake.learning.checkpoint import CheckpointError, save_checkpoint

REPO = pathlib.Path(__file__).resolve().parents[1]
SHIPPED = REPO / "models" / "cchp_default.pt"


def _clip(rng, n):
    return rng.normal(size=(n, 36)).astype(np.float32) * 0.3, rng.normal(size=(n, 6)).astype(np.float32) * 0.1


def _model(heads=1, key_source="state", kernel="dot", read_skip=False, read="attention", window=0, square=False):
    torch.manual_seed(0)
    model = Cchp(CchpConfig(attention_heads=heads, key_source=key_source, attention_kernel=kernel,
                            read_skip=read_skip, read=read, phi_window=window, phi_signed_square=square)).eval()
    model.normalizer.set_scales(torch.rand(36) * 0.5 + 0.1, torch.rand(6) * 0.2 + 0.05)
    return model


def _run_policy(policy, target_x, context, z=None):
    x_c, y_c, mask = collate_context(context)
    keys, values, z_mu, z_sigma = policy.encode_context(x_c, y_c, mask)
    h = torch.zeros(policy.hidden_size)
    c = torch.zeros(policy.hidden_size)
    y = torch.zeros(6)
    means, atts = [], []
    for t in range(len(target_x)):
        mean, std, h, c, att = policy.step(torch.from_numpy(target_x[t]), y, h, c, keys, values,
                                           z_mu if z is None else z)
        assert torch.all(std > 0)
        means.append(mean)
        atts.append(att)
        y = mean
    return torch.stack(means), atts, (keys, values, z_mu, z_sigma)


@pytest.mark.parametrize("heads,key_source,kernel,skip,read,window,square", [
    (1, "state", "dot", False, "attention", 0, False), (6, "state", "dot", False, "attention", 0, False),
    (1, "gesture", "dot", False, "attention", 0, False), (1, "gesture", "distance", True, "attention", 0, False),
    (6, "gesture", "distance", True, "attention", 0, False), (1, "gesture", "distance", True, "bayes_linear", 0, False),
    (1, "gesture", "distance", True, "bayes_linear", 10, False),
    (1, "gesture", "distance", True, "bayes_linear", 10, True)])
def test_whole_clip_matches_python_model(tmp_path, heads, key_source, kernel, skip, read, window, square):
    model = _model(heads, key_source, kernel, skip, read, window, square)
    rng = np.random.default_rng(heads)
    target = _clip(rng, 45)
    context = [_clip(rng, 40), _clip(rng, 28), _clip(rng, 13)]
    ref = model.predict(collate([target], [context]))["mean"][0]
    path = tmp_path / "policy.pt"
    torch.jit.save(script_policy(model), str(path))
    policy = torch.jit.load(str(path))  # torch.jit.load alone, as the Drake system does
    means, atts, (keys, values, z_mu, z_sigma) = _run_policy(policy, target[0], context)
    assert torch.allclose(means, ref, atol=1e-5), (means - ref).abs().max()
    k = 40 + 28 + 13
    assert keys.shape[0] == k and values.shape == (k, 6)
    assert z_mu.shape == (policy.latent_dim,) and z_sigma.shape == (policy.latent_dim,)
    assert torch.all(z_sigma > 0)
    assert atts[0].shape == ((k,) if heads == 1 else (heads, k))
    if read == "attention":  # a softmax; the Bayesian linear read's equivalent kernel is signed
        assert torch.allclose(atts[0].sum(-1), torch.ones(()), atol=1e-5)
    assert policy.feature_dim == 36 and policy.latent_dim == 32
    assert policy.hidden_size == 128 + (model.cfg.gesture_hidden_size if key_source == "gesture" else 0) + \
        max(0, window - 1) * 36
    assert torch.allclose(values, torch.from_numpy(np.concatenate([p[1] for p in context])))
    # step_read: the same step without the attention, which attention_of gives from its query.
    h = c = torch.zeros(policy.hidden_size)
    y = torch.zeros(6)
    for t in range(len(target[0])):
        mean, std, h, c, read, v, query = policy.step_read(torch.from_numpy(target[0][t]), y, h, c, keys, values, z_mu)
        assert torch.allclose(mean, means[t], atol=1e-6)
        assert query.shape == (policy.query_size,) and v.shape == (1,)
        att = policy.attention_of(query, keys)
        assert torch.allclose(att, atts[t], atol=1e-6)
        assert torch.allclose(read, torch.atleast_2d(att) @ values, atol=1e-6)
        y = mean


def test_step_reads_nan_features_as_zeros():
    policy = script_policy(_model())
    rng = np.random.default_rng(0)
    x_c, y_c, mask = collate_context([_clip(rng, 10)])
    keys, values, z_mu, _ = policy.encode_context(x_c, y_c, mask)
    h = c = torch.zeros(128)
    nan_out = policy.step(torch.full((36,), float("nan")), torch.zeros(6), h, c, keys, values, z_mu)
    zero_out = policy.step(torch.zeros(36), torch.zeros(6), h, c, keys, values, z_mu)
    assert torch.allclose(nan_out[0], zero_out[0])


def test_empty_context_mask_is_an_error():
    policy = script_policy(_model())
    with pytest.raises(Exception, match="no context step"):
        policy.encode_context(torch.zeros(1, 5, 36), torch.zeros(1, 5, 6), torch.zeros(1, 5, dtype=torch.bool))


def test_export_cli_and_bad_files(tmp_path):
    model = _model()
    ck = tmp_path / "ck.pt"
    save_checkpoint(ck, model, {"model": "cchp"}, step=1)
    out = tmp_path / "policy.pt"
    run = subprocess.run([sys.executable, "-m", "rtcohand_drake.export", "--checkpoint", str(ck), "--out", str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    policy = load_policy(out)
    assert policy.hidden_size == 128
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00garbage")
    for args in (["--checkpoint", str(bad)], ["--checkpoint", str(tmp_path / "missing.pt")],
                 ["--checkpoint", str(out)]):  # an export is not a checkpoint
        run = subprocess.run([sys.executable, "-m", "rtcohand_drake.export", *args, "--out", str(tmp_path / "x.pt")],
                             capture_output=True, text=True)
        assert run.returncode == 2
        lines = run.stderr.strip().splitlines()
        assert len(lines) == 1 and args[1] in lines[0] and "Traceback" not in run.stderr
    for p in (bad, ck, tmp_path / "missing.pt"):
        with pytest.raises(CheckpointError, match=str(p)):
            load_policy(p)
    truncated = tmp_path / "trunc.pt"
    truncated.write_bytes(out.read_bytes()[: out.stat().st_size // 2])
    with pytest.raises(CheckpointError, match=str(truncated)):
        load_policy(truncated)


@pytest.mark.parametrize("clamp", [False, True], ids=["unclamped", "clamped to the context's range"])
def test_context_prior_export_matches_python_model(clamp):
    """The signed-square block with its prior scaled by the context (and clamped to the context's
    range): the export computes what the model does."""
    torch.manual_seed(0)
    model = Cchp(CchpConfig(key_source="gesture", attention_kernel="distance", read_skip=True, read="bayes_linear",
                            phi_window=10, phi_signed_square=True, phi_signed_square_prior="context",
                            phi_signed_square_prior_weight=3.0, phi_signed_square_clamp=clamp)).eval()
    model.normalizer.set_scales(torch.rand(36) * 0.5 + 0.1, torch.rand(6) * 0.2 + 0.05)
    rng = np.random.default_rng(5)
    target = _clip(rng, 45)
    context = [_clip(rng, 40), _clip(rng, 28), _clip(rng, 13)]
    ref = model.predict(collate([target], [context]))["mean"][0]
    means, _, _ = _run_policy(script_policy(model), target[0], context)
    assert torch.allclose(means, ref, atol=1e-5), (means - ref).abs().max()


def test_label_lead_export_matches_python_model_and_reads_later_labels():
    """With label_lead, the read is solved for each context step's label that many steps on: the
    export computes what the model does, and its values are the labels shifted within each clip
    (a clip's last label repeated past its end)."""
    torch.manual_seed(0)
    model = Cchp(CchpConfig(key_source="gesture", attention_kernel="distance", read_skip=True, read="bayes_linear",
                            phi_window=10, phi_signed_square=True, phi_signed_square_prior="context",
                            phi_signed_square_prior_weight=3.0, label_lead=3)).eval()
    model.normalizer.set_scales(torch.rand(36) * 0.5 + 0.1, torch.rand(6) * 0.2 + 0.05)
    rng = np.random.default_rng(6)
    target = _clip(rng, 45)
    context = [_clip(rng, 40), _clip(rng, 28), _clip(rng, 13)]
    ref = model.predict(collate([target], [context]))["mean"][0]
    policy = script_policy(model)
    assert policy.label_lead == 3
    means, _, (_, values, _, _) = _run_policy(policy, target[0], context)
    assert torch.allclose(means, ref, atol=1e-5), (means - ref).abs().max()
    expected = np.concatenate([np.concatenate([y[3:], np.repeat(y[-1:], 3, 0)]) for _, y in context])
    assert np.allclose(values.numpy(), expected)
    # Without the lead the same weights read the unshifted labels, and the output differs.
    model.cfg.label_lead = 0
    plain = model.predict(collate([target], [context]))["mean"][0]
    assert (plain - ref).abs().max() > 1e-4


def test_label_lead_needs_the_bayes_linear_read():
    with pytest.raises(ValueError, match="label_lead"):
        Cchp(CchpConfig(label_lead=2))


def _card(model):
    return {"kind": "cchp", "model_config": model.cfg.to_dict(), "train_config": {}, "step": 7, "meta": {}}


@pytest.mark.parametrize("heads,key_source,read,window", [
    (1, "state", "attention", 0), (6, "gesture", "attention", 0), (1, "gesture", "bayes_linear", 10)])
def test_policy_rebuilt_from_its_file_computes_what_the_file_computes(tmp_path, heads, key_source, read, window):
    from rtcohand_drake.learning.export import cchp_from_policy, export_model

    model = _model(heads, key_source, "distance", True, read, window)
    path = export_model(model, _card(model), tmp_path / "policy.pt")
    rebuilt, card = cchp_from_policy(path)
    assert card["step"] == 7
    rebuilt_state = rebuilt.state_dict()
    for name, value in model.state_dict().items():
        if not (read == "bayes_linear" and name.startswith("attention.")):  # a key projection that read never runs
            assert torch.equal(value, rebuilt_state[name]), name
    rng = np.random.default_rng(2)
    target, context = _clip(rng, 30), [_clip(rng, 25), _clip(rng, 19)]
    original, _, _ = _run_policy(load_policy(path), target[0], context)
    again, _, _ = _run_policy(script_policy(rebuilt), target[0], context)
    assert torch.equal(original, again)


def test_export_from_policy_cli_changes_the_read_and_refuses_a_shape_change(tmp_path):
    from rtcohand_drake.learning.export import export_model, read_model_card

    model = _model(1, "gesture", "distance", True, "bayes_linear", 10)
    src = export_model(model, _card(model), tmp_path / "policy.pt")
    out = tmp_path / "ssq.pt"
    cli = [sys.executable, "-m", "rtcohand_drake.export", "--from-policy", str(src)]
    run = subprocess.run(cli + ["--set", "phi_signed_square=true", "--set", "phi_signed_square_prior=context",
                                "--out", str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    card = read_model_card(out)
    assert card["model_config"]["phi_signed_square_prior"] == "context"
    assert card["meta"]["derived_from"] == {"policy": "policy.pt", "set": {"phi_signed_square": True,
                                                                          "phi_signed_square_prior": "context"}}
    assert load_policy(out).phi_dim == load_policy(src).phi_dim + 36
    # The derived file is the model with that option: the same as building it in Python.
    derived = Cchp(CchpConfig(**card["model_config"])).eval()
    derived.load_state_dict(model.state_dict())
    rng = np.random.default_rng(3)
    target, context = _clip(rng, 30), [_clip(rng, 25), _clip(rng, 19)]
    ref = derived.predict(collate([target], [context]))["mean"][0]
    means, _, _ = _run_policy(load_policy(out), target[0], context)
    assert torch.allclose(means, ref, atol=1e-5)
    for bad in (["--set", "phi_size=32"], ["--set", "no_such_option=1"], ["--set", "oops"]):
        run = subprocess.run(cli + bad + ["--out", str(tmp_path / "x.pt")], capture_output=True, text=True)
        assert run.returncode == 2, run.stderr
        assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr


@pytest.mark.skipif(not SHIPPED.exists(), reason="models/cchp_default.pt not built yet")
def test_shipped_policy_loads_and_steps():
    assert SHIPPED.stat().st_size < 5_000_000
    policy = torch.jit.load(str(SHIPPED))
    assert policy.feature_dim == 36
    x_c, y_c, mask = torch.zeros(2, 20, 36), torch.zeros(2, 20, 6), torch.ones(2, 20, dtype=torch.bool)
    keys, values, z_mu, z_sigma = policy.encode_context(x_c, y_c, mask)
    assert keys.shape[0] == 40 and z_mu.shape == (policy.latent_dim,)
    out = policy.step(torch.zeros(36), torch.zeros(6), torch.zeros(policy.hidden_size),
                      torch.zeros(policy.hidden_size), keys, values, z_mu + z_sigma * torch.randn_like(z_sigma))
    assert out[0].shape == (6,) and out[1].shape == (6,) and torch.isfinite(out[0]).all()
