"""The Bayesian linear context read (CchpConfig.read = "bayes_linear"), exported, against numpy."""

import numpy as np
import pytest
import torch

from rtcohand_drake.learning.batching import collate, collate_context
from rtcohand_drake.learning.export import script_policy, unpack_blr_keys
from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig


def _clip(rng, n, scale=0.3):
    return rng.normal(size=(n, 36)).astype(np.float32) * scale, rng.normal(size=(n, 6)).astype(np.float32) * 0.1


def _model(window=10, **options):
    torch.manual_seed(3)
    model = Cchp(CchpConfig(key_source="gesture", attention_kernel="distance", read_skip=True,
                            read="bayes_linear", phi_window=window, **options)).eval()
    model.normalizer.set_scales(torch.rand(36) * 0.5 + 0.1, torch.rand(6) * 0.2 + 0.05)
    return model


def _play(policy, x, keys, values, z):
    h = torch.zeros(policy.hidden_size)
    c = torch.zeros(policy.hidden_size)
    y = torch.zeros(6)
    out = []
    for t in range(len(x)):
        mean, std, h, c, att = policy.step(torch.from_numpy(x[t]), y, h, c, keys, values, z)
        out.append((mean, std, att))
        y = mean
    return out


def _phis(model, x, fed_back):
    """phi(t) of a clip from a zero state, with fed_back[t] (twist, physical units) fed back after step t.

    The step feeds back its own means; `encode_context` feeds back the clip's labels.
    """
    x_n = model.normalizer_x(torch.from_numpy(x)).unsqueeze(0)
    win = model.blr.windows(x_n)
    fingers = model.cell.fingers(x_n)
    h = torch.zeros(1, model.cfg.state_size)
    c = torch.zeros(1, model.cfg.state_size)
    y_prev = torch.zeros(1, 6)
    phis = []
    for t in range(len(x)):
        h, c = model.cell(fingers[:, t], y_prev, h, c)
        phis.append(model.blr.features(h[:, model.cfg.hidden_size:], x_n[:, t], win[:, t])[0])
        y_prev = model.normalizer_y(torch.as_tensor(fed_back[t]).view(1, 6))
    return torch.stack(phis).double().numpy()


SIGNED_SQUARE_IN_CONTEXT = {"phi_signed_square": True, "phi_signed_square_prior": "context",
                            "phi_signed_square_prior_weight": 3.0}


def _prior(model, Phi):
    """The prior precision, here: lambda, and on the signed-square block (the 36 features before
    the constant) lambda * weight * that feature's mean square over the context."""
    lam = float(model.blr.lam.detach())
    prior = np.full(Phi.shape[1], lam)
    if model.cfg.phi_signed_square and model.cfg.phi_signed_square_prior == "context":
        d = Phi.shape[1]
        block = slice(d - 1 - 36, d - 1)
        prior[block] = lam * model.cfg.phi_signed_square_prior_weight * (Phi[:, block] ** 2).mean(0)
    return prior


@pytest.mark.parametrize("options", [{}, SIGNED_SQUARE_IN_CONTEXT, {**SIGNED_SQUARE_IN_CONTEXT, "phi_signed_square_clamp": True}],
                         ids=["fixed prior", "signed square, context prior", "signed square, clamped"])
def test_read_is_the_closed_form_posterior_mean(options):
    """r(t) = phi(t)^T (Phi^T Phi + Lambda)^-1 Phi^T Y, solved here in float64 numpy; with the clamp,
    phi(t)'s signed-square block first clamped to its range over the context steps."""
    model = _model(**options)
    rng = np.random.default_rng(0)
    context = [_clip(rng, 40), _clip(rng, 31), _clip(rng, 17)]
    target = _clip(rng, 25)[0]
    policy = script_policy(model)
    keys, values, z_mu, _ = policy.encode_context(*collate_context(context))
    steps = _play(policy, target, keys, values, z_mu)
    d = policy.phi_dim
    Phi = np.concatenate([_phis(model, x, y) for x, y in context])  # the context features, here
    Y = values.double().numpy() / model.normalizer.label_scale.double().numpy()
    gram = Phi.T @ Phi + np.diag(_prior(model, Phi))
    A = np.linalg.inv(gram)
    clamped = options.get("phi_signed_square_clamp", False)
    bounds = 72 if clamped else 0  # the signed-square block's lows and highs, after W
    assert keys.shape == (len(Phi), d + -(-(d * d + 6 * d + bounds) // len(Phi)))
    phi_a, a_packed, w_packed = unpack_blr_keys(keys, d)
    np.testing.assert_allclose(phi_a.double().numpy(), Phi @ A, atol=1e-5)
    np.testing.assert_allclose(a_packed.double().numpy(), A, atol=1e-6)
    W = np.linalg.solve(gram, Phi.T @ Y)
    np.testing.assert_allclose(w_packed.double().numpy(), W, atol=1e-5 * max(1.0, np.abs(W).max()))
    phi_t = _phis(model, target, [m for m, _, _ in steps])
    if clamped:
        block = slice(d - 1 - 36, d - 1)
        lo, hi = Phi[:, block].min(0), Phi[:, block].max(0)
        inside = np.clip(phi_t[:, block], lo, hi)
        assert np.abs(inside - phi_t[:, block]).max() > 1e-3  # the target does leave the context's range
        phi_t[:, block] = inside
    r_numpy = phi_t @ W
    r_policy = np.stack([(att.double() @ values.double()).numpy() for _, _, att in steps])
    r_policy = r_policy / model.normalizer.label_scale.double().numpy()
    np.testing.assert_allclose(r_policy, r_numpy, atol=1e-5 * max(1.0, np.abs(r_numpy).max()))
    # step_read's r = phi^T W, without the pass over the context, is the same read.
    H = policy.hidden_size
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    label_scale = model.normalizer.label_scale.double().numpy()
    r_read = []
    for t in range(len(target)):
        y, _, h, c, read, _, _ = policy.step_read(torch.from_numpy(target[t]), y, h, c, keys, values, z_mu)
        r_read.append(read[0].double().numpy() / label_scale)
    np.testing.assert_allclose(np.stack(r_read), r_numpy, atol=1e-5 * max(1.0, np.abs(r_numpy).max()))
    # The std is the heads' std times sqrt(1 + phi^T A phi): the ratio of two steps' stds, where
    # the heads' part is the same, cannot be checked directly, so check v against a model with the
    # variance left out through the packed A.
    v_numpy = 1.0 + np.einsum("ti,ij,tj->t", phi_t, A, phi_t)
    no_var = keys.clone()
    unpack_blr_keys(no_var, d)[1].zero_()  # A = 0: the same read, v = 1
    flat = _play(policy, target, no_var, values, z_mu)
    v_policy = np.stack([((s / s0) ** 2).double().numpy() for (_, s, _), (_, s0, _) in zip(steps, flat)])
    np.testing.assert_allclose(v_policy, np.repeat(v_numpy[:, None], 6, 1), rtol=1e-4)
    # ... and step_with_variance reports that same v beside the step's own outputs.
    H = policy.hidden_size
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    for t, (mean, std, _) in enumerate(steps):
        y2, std2, h, c, _, v = policy.step_with_variance(torch.from_numpy(target[t]), y, h, c, keys, values, z_mu)
        torch.testing.assert_close(y2, mean)
        torch.testing.assert_close(std2, std)
        assert float(v) == pytest.approx(v_numpy[t], rel=1e-4)
        y = y2


def test_std_grows_for_a_gesture_unlike_the_context():
    model = _model()
    rng = np.random.default_rng(1)
    context = [_clip(rng, 40, 0.1) for _ in range(4)]
    policy = script_policy(model)
    keys, values, z_mu, _ = policy.encode_context(*collate_context(context))
    near = _play(policy, _clip(rng, 10, 0.1)[0], keys, values, z_mu)
    far = _play(policy, _clip(rng, 10, 3.0)[0], keys, values, z_mu)
    std_near = torch.stack([s for _, s, _ in near]).mean()
    std_far = torch.stack([s for _, s, _ in far]).mean()
    assert std_far > 1.5 * std_near


def test_mirror_image_people_get_opposite_reads_from_the_same_gesture():
    """Person B makes the same hand motions as person A for the opposite twists: the context decides."""
    model = _model()
    rng = np.random.default_rng(2)
    person_a = [_clip(rng, 40) for _ in range(5)]
    person_b = [(x, -y) for x, y in person_a]
    gesture = _clip(rng, 20)[0]
    batch_a = collate([(gesture, np.zeros((20, 6), np.float32))], [person_a])
    batch_b = collate([(gesture, np.zeros((20, 6), np.float32))], [person_b])
    reads = []
    for batch in (batch_a, batch_b):
        ctx, _ = model.encode_context(batch)
        h = torch.zeros(1, model.cfg.state_size)
        c = torch.zeros(1, model.cfg.state_size)
        x_n = model.normalizer_x(batch.x)
        fingers = model.cell.fingers(x_n)
        win = model.blr.windows(x_n)
        out = []
        for t in range(20):
            h, c = model.cell(fingers[:, t], torch.zeros(1, 6), h, c)
            phi = model.blr.features(h[:, model.cfg.hidden_size:], x_n[:, t], win[:, t])
            r, _ = model.blr.read(phi, ctx.blr_W, ctx.blr_A)
            out.append(r)
        reads.append(torch.cat(out))
    assert reads[0].abs().max() > 1e-3
    torch.testing.assert_close(reads[0], -reads[1], atol=1e-5, rtol=1e-4)


def test_bayes_linear_needs_the_gesture_cell():
    with pytest.raises(ValueError):
        Cchp(CchpConfig(read="bayes_linear"))
    with pytest.raises(ValueError):
        Cchp(CchpConfig(read="bayes_linear", key_source="gesture", attention_heads=6))


def test_signed_square_gives_the_direction_of_an_asymmetric_stroke():
    """A sweep whose fast stroke carries the sign: out fast, back slowly, so the frames sum to ~0
    (no linear read sees the sign), while the sum of x |x| has the fast stroke's sign."""
    from rtcohand_drake.learning.nets.cchp import signed_square_sum

    fast, slow = np.full(3, 0.9), np.full(6, -0.45)  # 2.7 out, 2.7 back
    stroke = np.zeros((9, 36), np.float32)
    stroke[:, 7] = np.concatenate([fast, slow])
    window = torch.from_numpy(stroke.reshape(1, -1))
    assert abs(float(window.view(9, 36)[:, 7].sum())) < 1e-5
    forward = signed_square_sum(window)[0]
    backward = signed_square_sum(-window)[0]
    assert float(forward[7]) > 1.0 and float(backward[7]) < -1.0
    assert torch.count_nonzero(forward) == 1


def test_training_fit_is_the_same_closed_form_as_the_export():
    """BayesLinearRead.fit (what training differentiates through) gives numpy's W and A, with the
    context-scaled prior on the signed-square block and padded steps masked out."""
    model = _model(**SIGNED_SQUARE_IN_CONTEXT)
    rng = np.random.default_rng(1)
    d = model.blr.dim
    phi = rng.normal(size=(2, 50, d))
    phi[..., d - 1 - 36 : d - 1] *= rng.uniform(0.01, 5.0, size=36)  # scales a hundredfold apart
    y = rng.normal(size=(2, 50, 6))
    mask = np.ones((2, 50), bool)
    mask[1, 37:] = False
    W, A = model.blr.fit(torch.from_numpy(phi), torch.from_numpy(y), torch.from_numpy(mask))
    for b in range(2):
        P, Y = phi[b][mask[b]], y[b][mask[b]]
        gram = P.T @ P + np.diag(_prior(model, P))
        np.testing.assert_allclose(A[b].detach().numpy(), np.linalg.inv(gram), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(W[b].detach().numpy(), np.linalg.solve(gram, P.T @ Y), rtol=1e-6, atol=1e-9)


def test_context_prior_reads_the_signed_square_whatever_its_scale():
    """With the context prior, the read of a signed-square feature does not depend on that
    feature's units (it is the ridge on the standardised feature); with the fixed prior, a feature
    of small scale is shrunk to nothing."""
    rng = np.random.default_rng(2)
    reads = {}
    for prior in ("fixed", "context"):
        model = _model(phi_signed_square=True, phi_signed_square_prior=prior)
        d = model.blr.dim
        k = d - 1 - 36  # the first signed-square feature carries the label, at two scales
        for scale in (1.0, 0.01):
            phi = rng.normal(size=(1, 400, d)) * 0.01
            s = rng.normal(size=400)
            phi[0, :, k] = s * scale
            y = np.zeros((1, 400, 6))
            y[0, :, 0] = s
            W, _ = model.blr.fit(torch.from_numpy(phi), torch.from_numpy(y), torch.ones(1, 400, dtype=torch.bool))
            reads[prior, scale] = float(W.detach()[0, k, 0]) * scale  # the read of a unit of the label's signal
    assert reads["context", 1.0] == pytest.approx(reads["context", 0.01], rel=1e-3)
    assert reads["context", 0.01] > 0.9
    assert reads["fixed", 0.01] < 0.1


def test_unknown_signed_square_prior_is_refused():
    with pytest.raises(ValueError, match="phi_signed_square_prior"):
        _model(phi_signed_square=True, phi_signed_square_prior="learned")


def test_signed_square_clamp_needs_the_block():
    with pytest.raises(ValueError, match="phi_signed_square_clamp"):
        _model(phi_signed_square_clamp=True)
