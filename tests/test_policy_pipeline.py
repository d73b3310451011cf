"""The CCHP policy system and the replay source, alone and in the full diagram."""

import numpy as np
import pytest
import torch
from pydrake.systems.analysis import Simulator

from rtcohand_drake.data.dataset import load_policy_clips
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.data.dataset import write_dataset
from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.systems.gestures.replay import ReplayGestureSource
from rtcohand_drake.learning.policy_file import PolicyFileError, load_policy
from rtcohand_drake.data.sampling import pack_context
from rtcohand_drake.systems.policy import CchpPolicy
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.interfaces import GESTURE_FEATURES, RESUME_COUNT


@pytest.fixture(scope="module")
def policy_file(small_policy_file):
    return small_policy_file


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "two_users.h5"
    clips = generate_population(GeneratorConfig(), n_users=2, seed=3)
    write_dataset(path, clips if isinstance(clips, list) else list(clips))
    return path


def _offline_means(module, clip_features, pieces, z, with_reads=False):
    """The module's means over a clip (its own mean fed back) and, if asked, its context reads."""
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
    keys, values, _, _ = module.encode_context(x_c, y_c, mask)
    h = torch.zeros(int(module.hidden_size))
    c = torch.zeros(int(module.hidden_size))
    y = torch.zeros(6)
    means, reads = [], []
    with torch.no_grad():
        for x in clip_features:
            y, _, h, c, attention = module.step(torch.from_numpy(x.astype(np.float32)), y, h, c, keys, values,
                                                torch.from_numpy(z.astype(np.float32)))
            means.append(y.numpy().copy())
            reads.append(torch.mv(values.t(), attention).numpy().copy())  # one head: sum_k a_k y_k
    return (np.array(means), np.array(reads)) if with_reads else np.array(means)


@pytest.mark.parametrize("weight", [1.0, 0.5, 0.0])
def test_replay_through_the_diagram_matches_the_offline_module(policy_file, dataset, weight):
    """The policy's output is the module's mean (w = 1), the context read (w = 0) or between."""
    clips = load_policy_clips(dataset)
    target = clips[0]
    pieces = [(c.features, c.labels) for c in clips if c.user == target.user and c is not target][:5]
    scenario = load_scenario("inspection")
    policy = CchpPolicy(policy_file, pieces, scenario.policy.rate_hz, seed=4, correction_weight=weight)
    source = ReplayGestureSource([target], scenario.policy.rate_hz)
    run = build_run_diagram(scenario, source=source, policy=policy)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(source.end_time)
    log = run.loggers["policy_mean"].FindLog(simulator.get_context())
    times, means = log.sample_times(), log.data().T
    module_means, reads = _offline_means(load_policy(policy_file), target.features, pieces, policy.sample_z(0),
                                         with_reads=True)
    offline = weight * module_means + (1.0 - weight) * reads
    if weight < 1.0:
        assert np.max(np.abs(module_means - reads)) > 1e-3  # the blend is a different output
    # The log samples at each policy period; a sample at time k/rate shows the update made at (k-1)/rate.
    k = np.round(times * scenario.policy.rate_hz).astype(int)
    shown = k - 1
    ok = (shown >= 0) & (shown < len(offline))
    assert ok.sum() >= len(offline) - 2
    assert np.max(np.abs(means[ok] - offline[shown[ok]])) < 1e-4


@pytest.mark.parametrize("read", ["attention", "bayes_linear"])
def test_attention_port_is_the_steps_attention(tmp_path, dataset, read):
    """The attention port, computed from the step's query when evaluated, is the attention `step`
    returns for the same step; a policy file without `step_read` gives the same outputs."""
    from rtcohand_drake.learning.export import script_policy
    from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig

    torch.manual_seed(0)
    model = Cchp(CchpConfig(hidden_size=32, aggregate_sizes=[32, 32], latent_trunk_sizes=[32, 32], latent_dim=8,
                            key_size=16, output_hidden=[32], key_source="gesture", gesture_hidden_size=8,
                            read=read, phi_window=3 if read == "bayes_linear" else 0))
    model.normalizer.set_scales(torch.rand(36) * 0.5 + 0.1, torch.rand(6) * 0.2 + 0.05)
    module = script_policy(model.eval())
    clips = load_policy_clips(dataset)
    pieces = [(c.features, c.labels) for c in clips[1:4]]
    policy = CchpPolicy(module, pieces, 10.0, seed=2, correction_weight=0.5)

    class WithoutRead(torch.nn.Module):  # an older policy file: step and step_with_variance only
        def __init__(self, inner):
            super().__init__()
            self.inner = inner
            self.hidden_size, self.latent_dim = inner.hidden_size, inner.latent_dim

        def encode_context(self, *args):
            return self.inner.encode_context(*args)

        def step_with_variance(self, *args):
            return self.inner.step_with_variance(*args)

    older = CchpPolicy(WithoutRead(module), pieces, 10.0, seed=2, correction_weight=0.5)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
    keys, values, _, _ = module.encode_context(x_c, y_c, mask)
    contexts = [p.CreateDefaultContext() for p in (policy, older)]
    h = c = torch.zeros(module.hidden_size)
    y = torch.zeros(6)
    z = torch.from_numpy(policy.sample_z(0).astype(np.float32))
    for x in clips[0].features[:20]:
        for system, ctx in zip((policy, older), contexts):
            system.GetInputPort(GESTURE_FEATURES).FixValue(ctx, x)
            ctx.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(ctx))
        y, _, h, c, att = module.step(torch.from_numpy(x.astype(np.float32)), y, h, c, keys, values, z)
        shown = [system.GetOutputPort("attention").Eval(ctx) for system, ctx in zip((policy, older), contexts)]
        np.testing.assert_allclose(shown[0], att.numpy(), atol=1e-6)
        np.testing.assert_allclose(shown[1], att.numpy(), atol=1e-6)
        twists = [system.GetOutputPort("policy_mean").Eval(ctx) for system, ctx in zip((policy, older), contexts)]
        read = att.numpy() @ values.numpy()
        np.testing.assert_allclose(twists[0], read + 0.5 * (y.numpy() - read), atol=1e-5)
        np.testing.assert_allclose(twists[1], twists[0], atol=1e-6)


def test_policy_resamples_z_on_resume(policy_file, dataset):
    clips = load_policy_clips(dataset)
    pieces = [(c.features, c.labels) for c in clips[:3]]
    policy = CchpPolicy(policy_file, pieces, 10.0, seed=1)
    ctx = policy.CreateDefaultContext()
    z0 = ctx.get_discrete_state(4).get_value().copy()
    policy.GetInputPort(GESTURE_FEATURES).FixValue(ctx, np.zeros(36))
    policy.GetInputPort(RESUME_COUNT).FixValue(ctx, [1.0])
    state = policy.EvalUniquePeriodicDiscreteUpdate(ctx)
    z1 = state.get_vector(4).get_value()
    assert not np.allclose(z0, z1)
    assert np.allclose(z1, policy.sample_z(1))
    assert np.all(np.isfinite(state.get_vector(2).get_value()))  # the mean


def test_policy_never_outputs_nan(policy_file, dataset):
    clips = load_policy_clips(dataset)
    policy = CchpPolicy(policy_file, [(c.features, c.labels) for c in clips[:2]], 10.0)
    ctx = policy.CreateDefaultContext()
    policy.GetInputPort(GESTURE_FEATURES).FixValue(ctx, np.full(36, np.nan))
    policy.GetInputPort(RESUME_COUNT).FixValue(ctx, [0.0])
    state = policy.EvalUniquePeriodicDiscreteUpdate(ctx)
    assert np.all(np.isfinite(state.get_vector(2).get_value()))


@pytest.mark.parametrize("content, expected", [
    (b"", "not a TorchScript policy"),
    (b"this is not a zip file", "not a TorchScript policy"),
])
def test_bad_policy_file_is_one_line(tmp_path, content, expected):
    path = tmp_path / "bad.pt"
    path.write_bytes(content)
    with pytest.raises(PolicyFileError) as info:
        load_policy(path)
    assert str(path) in str(info.value) and expected in str(info.value) and "\n" not in str(info.value)


def test_truncated_policy_file(tmp_path, policy_file):
    path = tmp_path / "trunc.pt"
    path.write_bytes(policy_file.read_bytes()[: 4000])
    with pytest.raises(PolicyFileError, match="not a TorchScript policy"):
        load_policy(path)


def test_the_output_gain_scales_the_twist_and_nothing_else(policy_file, dataset):
    """`policy.output_gain` G: the box's twist is G times the twist it gives with G = 1, step by step
    (the module is still fed its own mean, so its state is the same); outside [1, 5] it is an error."""
    clips = load_policy_clips(dataset)
    pieces = [(c.features, c.labels) for c in clips[1:4]]
    boxes = [CchpPolicy(policy_file, pieces, 10.0, seed=2, output_gain=g) for g in (1.0, 2.5)]
    contexts = [b.CreateDefaultContext() for b in boxes]
    seen = []
    for x in clips[0].features[:30]:
        for box, ctx in zip(boxes, contexts):
            box.GetInputPort(GESTURE_FEATURES).FixValue(ctx, x)
            ctx.SetDiscreteState(box.EvalUniquePeriodicDiscreteUpdate(ctx))
        seen.append([np.array(box.GetOutputPort("policy_mean").Eval(ctx)) for box, ctx in zip(boxes, contexts)])
    plain, scaled = (np.array(s) for s in zip(*seen))
    assert np.abs(plain).max() > 1e-3
    np.testing.assert_allclose(scaled, 2.5 * plain, rtol=1e-12, atol=1e-15)
    assert load_scenario("inspection").policy.output_gain == 1.0  # the shipped scenario: the policy's own
    for bad in (0.5, float("nan"), 6.0):
        with pytest.raises(ValueError, match="output_gain"):
            CchpPolicy(policy_file, pieces, 10.0, output_gain=bad)
