"""CCHP, RANP and Dummy LSTM on random tensors: shapes, masks, bounds, gradients, checkpoints."""

import numpy as np
import pytest
import torch

from rtcohand_drake.learning.batching import collate
from rtcohand_drake.learning.nets.blocks import gaussian_kl
from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig
from rtcohand_drake.learning.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from rtcohand_drake.learning.nets.lstm import DummyLstm
from rtcohand_drake.learning.nets.ranp import Ranp, RanpConfig
from rtcohand_drake.learning.train import TrainConfig

SMALL = dict(hidden_size=16, finger_sizes=[6, 8, 8], hand_hidden=[16], hand_feature_size=8,
             aggregate_sizes=[16, 16], latent_trunk_sizes=[16, 16], latent_dim=4, key_size=8, output_hidden=[16])


def _clip(rng, n):
    return rng.normal(size=(n, 36)).astype(np.float32), rng.normal(size=(n, 6)).astype(np.float32)


def _batch(seed=0, b=3):
    rng = np.random.default_rng(seed)
    targets = [_clip(rng, int(rng.integers(8, 20))) for _ in range(b)]
    contexts = [[_clip(rng, int(rng.integers(5, 15))) for _ in range(int(rng.integers(1, 4)))] for _ in range(b)]
    return targets, contexts


def _models():
    return [Cchp(CchpConfig(**SMALL)), Cchp(CchpConfig(**SMALL, attention_heads=6)),
            Cchp(CchpConfig(**SMALL, key_source="gesture", gesture_hidden_size=8)),
            Ranp(RanpConfig(**SMALL, window=4)), DummyLstm()]


@pytest.mark.parametrize("model", _models(), ids=["cchp", "cchp6", "cchp_gesture_keys", "ranp", "lstm"])
def test_forward_backward_and_predict(model):
    torch.manual_seed(0)
    targets, contexts = _batch()
    batch = collate(targets, contexts)
    terms = model(batch, p_tf=0.5, generator=torch.Generator().manual_seed(0), x_noise_std=1e-3)
    for k in ("loss", "nll", "kl", "mse"):
        assert terms[k].dim() == 0 and torch.isfinite(terms[k])
    assert terms["kl"] >= 0
    terms["loss"].backward()
    for name, p in model.named_parameters():
        assert p.grad is not None, f"no gradient reaches {name}"
    pred = model.predict(batch)
    assert pred["mean"].shape == batch.y.shape and pred["std"].shape == batch.y.shape


def test_std_bounded_below_in_label_units():
    model = Cchp(CchpConfig(**SMALL))
    scale = torch.tensor([0.1, 0.2, 0.3, 1.0, 2.0, 3.0])
    model.normalizer.set_scales(torch.ones(36), scale)
    with torch.no_grad():
        for b in model.output.net.biases:
            b.fill_(-50.0)  # push the std logits very low
    pred = model.predict(collate(*_batch()))
    assert torch.all(pred["std"] >= model.cfg.std_min * scale - 1e-6)


def test_kl_of_identical_gaussians_is_zero():
    mu, sigma = torch.randn(5, 4), torch.rand(5, 4) + 0.1
    assert torch.allclose(gaussian_kl(mu, sigma, mu, sigma), torch.zeros(5), atol=1e-6)
    assert torch.all(gaussian_kl(mu + 1, sigma, mu, sigma) > 0)


@pytest.mark.parametrize("model", _models(), ids=["cchp", "cchp6", "cchp_gesture_keys", "ranp", "lstm"])
def test_padding_does_not_change_a_clip(model):
    """A target batched with longer targets and contexts gets the same prediction as alone."""
    model.eval()
    targets, contexts = _batch(seed=1, b=3)
    alone = model.predict(collate(targets[:1], contexts[:1]))["mean"][0]
    together = model.predict(collate(targets, contexts))["mean"][0, : len(alone)]
    assert torch.allclose(alone, together, atol=1e-5)
    g = lambda: torch.Generator().manual_seed(0)
    one = model(collate(targets[:1], contexts[:1]), sample_posterior=False, generator=g())["loss_per_clip"][0]
    both = model(collate(targets, contexts), sample_posterior=False, generator=g())["loss_per_clip"][0]
    assert torch.allclose(one, both, rtol=1e-4, atol=1e-3)


def test_context_order_does_not_matter():
    model = Cchp(CchpConfig(**SMALL)).eval()
    targets, contexts = _batch(seed=2, b=1)
    contexts = [[_clip(np.random.default_rng(5), 7), _clip(np.random.default_rng(6), 11)]]
    a = model.predict(collate(targets, contexts))["mean"]
    b = model.predict(collate(targets, [contexts[0][::-1]]))["mean"]
    assert torch.allclose(a, b, atol=1e-5)


def test_full_teacher_forcing_feeds_the_ground_truth():
    """With p_TF = 1 a step's output cannot depend on the previous step's prediction."""
    model = Cchp(CchpConfig(**SMALL)).eval()
    batch = collate(*_batch(seed=3, b=2))
    ctx, _ = model.encode_context(batch)
    z = ctx.z_mu
    x, y = model.normalizer_x(batch.x), model.normalizer_y(batch.y)
    m1, _, _ = model.decode(x, ctx, z, y_teacher=y, p_tf=1.0)
    with torch.no_grad():
        model.output.net.biases[-1][:, 0] += 1.0  # shifts every predicted mean by 1
    m2, _, _ = model.decode(x, ctx, z, y_teacher=y, p_tf=1.0)
    assert torch.allclose(m2 - m1, torch.ones_like(m1), atol=1e-5)
    m3, _, _ = model.decode(x, ctx, z)  # free-running: the shift feeds back
    assert not torch.allclose(m3 - m1, torch.ones_like(m1), atol=1e-3)


def test_teacher_forcing_schedules():
    cfg = TrainConfig(steps=1600, tf_hold_steps=600)
    assert cfg.p_tf(0) == pytest.approx(0.9) and cfg.p_tf(599) == pytest.approx(0.9)
    assert cfg.p_tf(1100) == pytest.approx(0.45)
    assert cfg.p_tf(1600) == pytest.approx(0.0)
    assert cfg.p_tf(800) > cfg.p_tf(900)
    short_decay = TrainConfig(steps=4000, tf_hold_steps=300, tf_decay_steps=1200)
    assert short_decay.p_tf(900) == pytest.approx(0.45)
    assert short_decay.p_tf(1500) == short_decay.p_tf(3999) == pytest.approx(0.0)
    fixed = TrainConfig(tf_schedule="fixed:0.9")
    assert fixed.p_tf(0) == fixed.p_tf(10_000) == pytest.approx(0.9)


def test_default_sizes_follow_the_paper():
    model = Cchp()
    assert model.cell.fingers.net[0].in_features == 6
    assert model.cell.hand[0].in_features == 320  # 6 parts x 32 + H
    assert model.cell.lstm.hidden_size == 128
    assert model.latent.aggregate[0].in_features == 134  # H + 6
    assert model.latent.mu_head.out_features == 32
    assert model.attention.kq.out_features == 32


def test_checkpoint_roundtrip_and_errors(tmp_path):
    model = Cchp(CchpConfig(**SMALL))
    model.normalizer.set_scales(torch.rand(36) + 0.5, torch.rand(6) + 0.5)
    path = tmp_path / "ck.pt"
    save_checkpoint(path, model, {"model": "cchp", "seed": 3}, step=7, meta={"train_time_s": 1.5})
    loaded, payload = load_checkpoint(path)
    assert payload["step"] == 7 and payload["train_config"]["seed"] == 3
    batch = collate(*_batch())
    assert torch.allclose(model.eval().predict(batch)["mean"], loaded.predict(batch)["mean"])
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    truncated = tmp_path / "trunc.pt"
    truncated.write_bytes(path.read_bytes()[:500])
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    for p in (bad, truncated, foreign, tmp_path / "missing.pt"):
        with pytest.raises(CheckpointError) as err:
            load_checkpoint(p)
        assert str(p) in str(err.value) and "\n" not in str(err.value)


def test_beta_nll_changes_the_objective_not_the_reported_elbo():
    model = Cchp(CchpConfig(**SMALL))
    batch = collate(*_batch(seed=4))
    g = lambda: torch.Generator().manual_seed(0)
    plain = model(batch, generator=g())
    beta = model(batch, generator=g(), nll_beta=1.0)
    assert torch.allclose(plain["elbo_loss"], beta["elbo_loss"])
    assert torch.allclose(plain["loss"], plain["elbo_loss"])
    assert not torch.allclose(beta["loss"], beta["elbo_loss"])


def test_gesture_keys_do_not_see_the_labels():
    """With "gesture" keys, the context's keys depend on its hand motion only:
    changing the context labels changes the values and the latent, not the keys."""
    torch.manual_seed(0)
    model = Cchp(CchpConfig(**SMALL, key_source="gesture", gesture_hidden_size=8)).eval()
    targets, contexts = _batch()
    relabelled = [[(x, -2.0 * y) for x, y in c] for c in contexts]
    a, _ = model.encode_context(collate(targets, contexts))
    b, _ = model.encode_context(collate(targets, relabelled))
    assert torch.equal(a.keys, b.keys)
    assert not torch.allclose(a.values, b.values)
    state = Cchp(CchpConfig(**SMALL)).eval()  # the paper's keys read h, which is fed the labels
    a, _ = state.encode_context(collate(targets, contexts))
    b, _ = state.encode_context(collate(targets, relabelled))
    assert not torch.allclose(a.keys, b.keys)


@pytest.mark.parametrize("heads", [1, 6])
def test_readout_loss_is_the_context_read_error(heads):
    """The readout term adds weight * 0.5 * sum_t |r(t) - y(t)|^2 to the loss and
    nothing to the ELBO; its gradient reaches the attention's projection."""
    torch.manual_seed(0)
    model = Cchp(CchpConfig(**SMALL, key_source="gesture", gesture_hidden_size=8, attention_heads=heads))
    batch = collate(*_batch())

    def terms(w):
        return model(batch, p_tf=1.0, sample_posterior=False, readout_weight=w)

    plain, with_read = terms(0.0), terms(2.0)
    assert "readout_mse" not in plain and with_read["readout_mse"] > 0
    assert torch.allclose(plain["elbo_loss"], with_read["elbo_loss"])
    steps_per_clip = batch.mask.sum() / batch.mask.shape[0]
    expected = plain["loss"] + 2.0 * 0.5 * with_read["readout_mse"] * 6 * steps_per_clip
    assert torch.allclose(with_read["loss"], expected, rtol=1e-4)
    model.zero_grad()
    (with_read["loss"] - plain["loss"]).backward()
    assert model.attention.kq.weight.grad.abs().sum() > 0


def test_read_skip_adds_the_context_read_to_the_mean():
    torch.manual_seed(0)
    model = Cchp(CchpConfig(**SMALL, key_source="gesture", gesture_hidden_size=8, attention_kernel="distance",
                            read_skip=True)).eval()
    with torch.no_grad():  # f_y outputs zero: the mean is the read alone
        for w, b in zip(model.output.net.weights, model.output.net.biases):
            w.zero_()
            b.zero_()
    batch = collate(*_batch())
    ctx, _ = model.encode_context(batch)
    reads = []
    mean, _, _ = model.decode(model.normalizer_x(batch.x), ctx, ctx.z_mu, readouts=reads)
    read = torch.stack(reads, 1)[:, :, 0]
    assert torch.allclose(mean, read) and read.abs().max() > 0


def test_label_lead_trains_on_the_labels_that_many_steps_on():
    """With label_lead k the loss scores each step's mean against the label k steps later (a clip's
    last label repeated past its end), and the read is solved for the context's shifted labels."""
    from rtcohand_drake.learning.nets.cchp import lead_labels

    torch.manual_seed(0)
    cfg = dict(SMALL, key_source="gesture", gesture_hidden_size=8, read="bayes_linear", phi_size=8, label_lead=2)
    model = Cchp(CchpConfig(**cfg))
    batch = collate(*_batch())
    terms = model(batch, p_tf=0.0, sample_posterior=False)
    h_c, h_t = model.encode_context_and_target(batch)
    ctx, stats = model.encode_context(batch, h_c)
    z, _ = model.posterior(batch, stats, h_t)
    mean = model.decode(model.normalizer_x(batch.x), ctx, z)[0] * model.normalizer.label_scale
    m = batch.mask.float()
    target = torch.zeros_like(batch.y)
    for i, n in enumerate(batch.mask.sum(1).tolist()):  # written out: y[min(t + 2, n - 1)]
        target[i, :n] = batch.y[i, [min(t + 2, n - 1) for t in range(n)]]
    assert torch.allclose(lead_labels(batch.y, batch.mask, 2) * m.unsqueeze(-1), target)
    expected = ((((target - mean) ** 2).mean(-1) * m).sum(1) / m.sum(1)).mean()
    assert torch.allclose(terms["mse"], expected, rtol=1e-5)
    unshifted = ((((batch.y - mean) ** 2).mean(-1) * m).sum(1) / m.sum(1)).mean()
    assert not torch.allclose(terms["mse"], unshifted, rtol=1e-3)


def test_checkpoint_loads_with_a_read_option_changed_and_refuses_a_shape_change(tmp_path):
    """`evaluate --set`: an option that holds no parameters changes how the loaded model reads its
    context; one that changes a weight's shape is a one-line CheckpointError."""
    options = dict(key_source="gesture", attention_kernel="distance", read_skip=True, read="bayes_linear",
                   phi_window=4, phi_signed_square=True, phi_signed_square_prior="context")
    model = Cchp(CchpConfig(**SMALL, **options))
    path = tmp_path / "ck.pt"
    save_checkpoint(path, model, {"model": "cchp"}, step=1)
    plain, _ = load_checkpoint(path)
    clamped, _ = load_checkpoint(path, {"phi_signed_square_clamp": True})
    assert not plain.blr.clamp and clamped.blr.clamp
    for a, b in zip(plain.state_dict().values(), clamped.state_dict().values()):
        assert torch.equal(a, b)
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(path, {"phi_window": 6})
    assert str(path) in str(err.value) and "\n" not in str(err.value)
