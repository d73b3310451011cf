"""A policy file that blends the CCHP, per person, with a ridge read of their own clips
(learning.ridge_blend_policy), checked against its definition written out in numpy."""

import pathlib
import subprocess
import sys

import numpy as np
import pytest
import torch

from rtcohand_drake.data.hand_features import FEATURE_DIM
from rtcohand_drake.data.sampling import pack_context
from rtcohand_drake.learning import ridge_blend_policy as rbp
from rtcohand_drake.learning.policy_file import load_policy
from rtcohand_drake.learning.ridge_reference import RidgeReference

MODELS = pathlib.Path(__file__).resolve().parents[1] / "models"
CORE = MODELS / "cchp_default.pt"  # the shipped CCHP


def _stepped(module, x, keys, values, z, read=False):
    """(T, 6) means of a module stepped over x from a zero state, its own mean fed back (by `step_read`,
    as a wrapping file steps its inner file, with `read`)."""
    H = int(module.hidden_size)
    h, c, y = torch.zeros(H), torch.zeros(H), torch.zeros(6)
    out = []
    with torch.no_grad():
        for xt in torch.from_numpy(np.ascontiguousarray(x, np.float32)):
            if read:
                y, _, h, c, _, _, _ = module.step_read(xt, y, h, c, keys, values, z)
            else:
                y, _, h, c, _ = module.step(xt, y, h, c, keys, values, z)
            out.append(y.numpy().astype(np.float64))
    return np.array(out)


def _linear_person(rng, n_clips=12, steps=30, window=3):
    """Clips whose labels are a fixed linear map of the last `window` steps of their features."""
    mix = rng.normal(scale=0.05, size=(window * FEATURE_DIM, 6))
    pieces = []
    for _ in range(n_clips):
        x = rng.normal(scale=0.3, size=(steps, FEATURE_DIM))
        windows = np.hstack([np.vstack([np.zeros((window - 1 - j, FEATURE_DIM)), x[:steps - (window - 1 - j)]])
                             for j in range(window)])
        pieces.append((x.astype(np.float32), (windows @ mix).astype(np.float32)))
    return pieces


def _led(y, lead):
    """Each step's label `lead` steps on, the clip's last label held past its end."""
    return np.vstack([y[lead:], np.repeat(y[-1:], min(lead, len(y)), 0)]) if lead else y


def _numpy_sums(inner, pieces, window, lam, folds, rows, lead=0):
    """Per clip (gap . miss, |gap|^2, |miss|^2) as the module docstring defines them, written out: clip b
    in fold b mod F, read with the other folds' clips as context by the CCHP (stepped, its own mean fed
    back, z the prior mean) and by the ridge fitted on them; gap = ridge - CCHP, miss = label - CCHP,
    over every step of every stride-th clip (other clips' rows zero). With `lead`, the ridge is fitted to
    the labels that many steps on and the miss taken against them; the CCHP reads the labels as they are."""
    stride = max(1, len(pieces) // rows)
    sums = np.zeros((len(pieces), 3))
    for f in range(min(folds, len(pieces))):
        inside = [p for b, p in enumerate(pieces) if b % folds != f]
        ridge = RidgeReference(window, lam).fit([(x, _led(y, lead)) for x, y in inside])
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(inside))
        keys, values, z, _ = inner.encode_context(x_c, y_c, mask)
        for b, (x, y) in enumerate(pieces):
            if b % folds != f or b % stride:
                continue
            own = _stepped(inner, x, keys, values, z)
            gap, miss = ridge.predict(x) - own, _led(y, lead) - own
            sums[b] = [(gap * miss).sum(), (gap * gap).sum(), (miss * miss).sum()]
    return sums, stride


def _numpy_blend(inner, pieces, window, lam, folds, rows, lead=0):
    """B: the least-squares blend over the stepped clips."""
    sums, _ = _numpy_sums(inner, pieces, window, lam, folds, rows, lead)
    return float(np.clip(sums[:, 0].sum() / sums[:, 1].sum(), 0.0, 1.0))


def _numpy_gain(inner, pieces, window, lam, folds, rows):
    """The share of the CCHP's squared error the blend removes, cross-fitted: the stepped clips taken
    alternately into two halves, each read with the B of the other half."""
    sums, stride = _numpy_sums(inner, pieces, window, lam, folds, rows)
    stepped = np.arange(0, len(pieces), stride)
    halves = [sums[stepped[0::2]].sum(0), sums[stepped[1::2]].sum(0)]
    removed = 0.0
    for i in (0, 1):
        b = float(np.clip(halves[1 - i][0] / halves[1 - i][1], 0.0, 1.0))
        miss_after = halves[i][2] - 2 * b * halves[i][0] + b * b * halves[i][1]  # |miss - b gap|^2
        removed += halves[i][2] - miss_after
    return removed / sums[:, 2].sum()


@pytest.mark.parametrize("lead", [0, 2])
def test_the_blend_reads_as_its_definition(tmp_path, lead):
    """With `--lead L` the ridge is fitted to, and B chosen on, each context step's label L steps on."""
    rng = np.random.default_rng(0)
    path = rbp.build_ridge_blend_policy(CORE, tmp_path / "blend.pt", window=3, lam=5.0, folds=3, rows=4, lead=lead)
    blend, inner = load_policy(path), load_policy(CORE)
    pieces = _linear_person(rng, n_clips=8)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
    keys, values, z, _ = blend.encode_context(x_c, y_c, mask)
    b = float(blend.blend_of(keys))
    assert b == pytest.approx(_numpy_blend(inner, pieces, 3, 5.0, 3, 4, lead), abs=2e-4)
    inner_keys, inner_values, inner_z, _ = inner.encode_context(x_c, y_c, mask)
    # The keys' memory starts with the inner file's keys, as they are.
    k, d_in = inner_keys.shape
    assert torch.equal(keys.reshape(-1)[:k * d_in].view(k, d_in), inner_keys) and torch.equal(values, inner_values)
    target, _ = _linear_person(rng, n_clips=1)[0]
    expected = (b * RidgeReference(3, 5.0).fit([(x, _led(y, lead)) for x, y in pieces]).predict(target)
                + (1.0 - b) * _stepped(inner, target, inner_keys, inner_values, inner_z))
    np.testing.assert_allclose(_stepped(blend, target, keys, values, z), expected, atol=2e-4)


def test_a_person_a_linear_read_fits_is_read_as_well_as_that_read(tmp_path):
    """On clips the test writes: a person whose commands are a linear map of their recent motion.
    The per-person choice leans on the ridge, and the file reads their held-out clips about as well
    as the ridge alone, far better than the CCHP alone."""
    rng = np.random.default_rng(1)
    path = rbp.build_ridge_blend_policy(CORE, tmp_path / "blend.pt", window=3, lam=1.0)
    blend, inner = load_policy(path), load_policy(CORE)
    person = _linear_person(rng, n_clips=16)
    context, held_out = person[:12], person[12:]
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z, _ = blend.encode_context(x_c, y_c, mask)
    inner_keys, inner_values, inner_z, _ = inner.encode_context(x_c, y_c, mask)
    ridge = RidgeReference(3, 1.0).fit(context)
    errors = {"file": 0.0, "ridge": 0.0, "cchp": 0.0}
    for x, y in held_out:
        errors["file"] += float(((_stepped(blend, x, keys, values, z) - y) ** 2).sum())
        errors["ridge"] += float(((ridge.predict(x) - y) ** 2).sum())
        errors["cchp"] += float(((_stepped(inner, x, inner_keys, inner_values, inner_z) - y) ** 2).sum())
    assert float(blend.blend_of(keys)) > 0.8
    assert errors["file"] <= 1.2 * errors["ridge"] and errors["file"] < 0.5 * errors["cchp"]


def test_building_on_a_blended_file_or_bad_settings_is_one_line(tmp_path):
    cli = [sys.executable, "-m", "rtcohand_drake.learning.ridge_blend_policy"]
    blended = rbp.build_ridge_blend_policy(CORE, tmp_path / "blend.pt")
    for args in (["--policy", str(blended)], ["--policy", str(CORE), "--lambda", "0"],
                 ["--policy", str(CORE), "--lead", "-1"], ["--policy", str(tmp_path / "none.pt")]):
        run = subprocess.run(cli + args + ["--out", str(tmp_path / "x.pt")], capture_output=True, text=True)
        assert run.returncode == 2, run.stderr
        assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr


def test_the_ridge_is_used_only_for_a_person_it_reads_better(tmp_path):
    """`--min-gain G`: B as fitted where the blend removes at least G of the inner read's squared error
    over the person's own clips, cross-fitted (checked against its definition written out); else B = 0
    and the file reads the person exactly as the inner file does."""
    rng = np.random.default_rng(2)
    pieces = _linear_person(rng, n_clips=8)
    inner = load_policy(CORE)
    gain = _numpy_gain(inner, pieces, 3, 5.0, 3, 4)
    assert 0.2 < gain < 0.99  # a linear person: the ridge reads them far better
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
    target, _ = _linear_person(rng, n_clips=1)[0]
    inner_keys, inner_values, inner_z, _ = inner.encode_context(x_c, y_c, mask)
    alone = _stepped(inner, target, inner_keys, inner_values, inner_z)
    for min_gain, used in ((gain - 0.05, True), (min(gain + 0.05, 0.999), False)):
        blend = load_policy(rbp.build_ridge_blend_policy(CORE, tmp_path / f"b{used}.pt", window=3, lam=5.0, folds=3,
                                                         rows=4, min_gain=min_gain))
        keys, values, z, _ = blend.encode_context(x_c, y_c, mask)
        b_used, b_fitted, b_gain = (float(v) for v in blend.blend_choice(keys))
        assert b_gain == pytest.approx(gain, abs=1e-3)
        assert b_fitted == pytest.approx(_numpy_blend(inner, pieces, 3, 5.0, 3, 4), abs=2e-4)
        assert b_used == (b_fitted if used else 0.0)
        if not used:
            np.testing.assert_allclose(_stepped(blend, target, keys, values, z), alone, atol=1e-6)


def _numpy_switch_figures(inner, pieces, window, lam, folds, rows):
    """(ridge_cv, cchp_cv) as the module docstring defines them, written out: clip b in fold b mod F; the
    ridge fitted on the other folds' clips reads every clip of the fold; the CCHP, with the other folds'
    clips as context, is stepped through the fold's clips among the `rows` spread over the context
    (round(linspace(0, n - 1, rows))); each a share of zero twist's squared error over the steps read."""
    picked = sorted({int(b) for b in np.round(np.linspace(0, len(pieces) - 1, min(rows, len(pieces))))})
    sums = np.zeros((2, 2))  # (ridge, cchp) x (error, zero)
    for f in range(min(folds, len(pieces))):
        inside = [p for b, p in enumerate(pieces) if b % folds != f]
        ridge = RidgeReference(window, lam).fit(inside)
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(inside))
        keys, values, z, _ = inner.encode_context(x_c, y_c, mask)
        for b, (x, y) in enumerate(pieces):
            if b % folds != f:
                continue
            sums[0] += [((ridge.predict(x) - y) ** 2).sum(), (y.astype(np.float64) ** 2).sum()]
            if b in picked:
                sums[1] += [((_stepped(inner, x, keys, values, z) - y) ** 2).sum(), (y.astype(np.float64) ** 2).sum()]
    return sums[0, 0] / sums[0, 1], sums[1, 0] / sums[1, 1]


def _unlinear_person(rng, n_clips=8, steps=30):
    """Clips whose labels no linear map of the features gives: the sign of a product of two features."""
    pieces = []
    for _ in range(n_clips):
        x = rng.normal(scale=0.3, size=(steps, FEATURE_DIM))
        y = np.zeros((steps, 6))
        y[:, 0] = 0.5 * np.sign(x[:, 0] * x[:, 1])
        y[:, 5] = 0.8 * np.sign(x[:, 2] * x[:, 3])
        pieces.append((x.astype(np.float32), y.astype(np.float32)))
    return pieces


def test_the_switch_gives_a_person_the_ridge_or_the_inner_file_whole_by_its_definition(tmp_path):
    """`--switch-below T --switch-ratio R`: the ridge alone (B = 1) for a person whose clips it reads, by
    folds, under T of zero twist's squared error and under R times the inner file's (each checked against
    its definition written out in numpy); else the inner file alone, exactly, and the inner file is not
    stepped at all where the ridge's own figure is over T."""
    rng = np.random.default_rng(3)
    inner = load_policy(CORE)
    linear, unlinear = _linear_person(rng, n_clips=8), _unlinear_person(rng)
    ridge_cv, cchp_cv = _numpy_switch_figures(inner, linear, 3, 5.0, 3, 4)
    assert ridge_cv < 0.05 and cchp_cv > 0.5  # a linear person: the ridge reads their clips far better
    target, _ = _linear_person(rng, n_clips=1)[0]
    cases = ((linear, dict(switch_below=0.1, switch_ratio=0.9), 1.0),
             (linear, dict(switch_below=ridge_cv * 0.9, switch_ratio=0.9), 0.0),  # over T
             (linear, dict(switch_below=0.1, switch_ratio=ridge_cv / cchp_cv * 0.9), 0.0),  # over R x cchp_cv
             (unlinear, dict(switch_below=0.1, switch_ratio=0.9), 0.0))
    for i, (person, switch, used) in enumerate(cases):
        module = load_policy(rbp.build_ridge_blend_policy(CORE, tmp_path / f"s{i}.pt", window=3, lam=5.0, folds=3,
                                                          rows=4, **switch))
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(person))
        keys, values, z, _ = module.encode_context(x_c, y_c, mask)
        b_used, b_fitted, _ = (float(v) for v in module.blend_choice(keys))
        figures = [float(v) for v in module.switch_figures(keys)]
        assert b_used == b_fitted == used
        if person is linear:
            assert figures[0] == pytest.approx(ridge_cv, rel=1e-6)
            if figures[0] < switch["switch_below"]:
                assert figures[1] == pytest.approx(cchp_cv, rel=2e-3)
            else:
                assert figures[1] == -1.0
        else:
            assert figures[0] > 0.5 and figures[1] == -1.0  # the ridge cannot read them: the inner file not stepped
        inner_keys, inner_values, inner_z, _ = inner.encode_context(x_c, y_c, mask)
        stepped = _stepped(module, target, keys, values, z)
        if used:
            expected = RidgeReference(3, 5.0).fit(person).predict(target)
            np.testing.assert_allclose(stepped, expected, atol=1e-4)
        else:
            assert np.array_equal(stepped, _stepped(inner, target, inner_keys, inner_values, inner_z, read=True))
    with pytest.raises(Exception, match="switch_below"):
        rbp.build_ridge_blend_policy(CORE, tmp_path / "bad.pt", switch_below=1.5)


def test_the_kernel_read_over_the_switch_gives_a_linear_person_the_ridge_and_a_path_and_shape_person_the_kernel_read(
        tmp_path):
    """The default file's kernel read of the path and shape built over the ridge switch over the shipped CCHP
    (`path_shape_policy --policy SWITCH.pt`; docs/policy.md: reported once, not shipped), on people the test
    writes: a person whose commands are a linear map of their last second of motion gets the ridge alone,
    reading their held-out clips as the ridge fitted to them does and far better than the CCHP; a
    fast-turning person whom only the path and shape tell is read, step for step, as by the kernel-read
    file over the CCHP alone (the switch leaves the CCHP; to float32 rounding), and gets the kernel read."""
    from rtcohand_drake.data.hand_features import PATH_SHAPE_DIM
    from rtcohand_drake.learning.path_shape_policy import FAST_TURN_RAD_S, build_path_shape_policy

    switch = rbp.build_ridge_blend_policy(CORE, tmp_path / "switch.pt", switch_below=0.1, switch_ratio=0.9)
    one, core = load_policy(build_path_shape_policy(switch, tmp_path / "one.pt")), load_policy(CORE)
    rng = np.random.default_rng(4)
    person = []  # a direct person: each command 0.5 x the palm's motion on its axis now
    for _ in range(16):
        x = rng.normal(scale=0.3, size=(100, FEATURE_DIM)).astype(np.float32)
        person.append((x, (0.5 * x[:, :6]).astype(np.float32)))
    context, held_out = person[:12], person[12:]
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z, _ = one.encode_context(x_c, y_c, mask)  # the 36 features alone: the inner read
    switch_keys = one._inner_keys(keys)
    assert float(one.inner.blend_choice(switch_keys)[0]) == 1.0 and float(one.blend_choice(keys)[0]) == 0.0
    core_keys, core_values, core_z, _ = core.encode_context(x_c, y_c, mask)
    ridge = RidgeReference(10, 100.0).fit(context)
    errors = {"file": 0.0, "ridge": 0.0, "cchp": 0.0}
    for x, y in held_out:
        read = _stepped(one, x, keys, values, z)
        np.testing.assert_allclose(read, ridge.predict(x), atol=1e-4)
        errors["file"] += float(((read - y) ** 2).sum())
        errors["ridge"] += float(((ridge.predict(x) - y) ** 2).sum())
        errors["cchp"] += float(((_stepped(core, x, core_keys, core_values, core_z) - y) ** 2).sum())
    assert errors["file"] <= 1.01 * errors["ridge"] and errors["file"] < 0.2 * errors["cchp"]

    # A fast-turning person whose commands only the hand's path and shape tell.
    def pieces(lengths):
        out = []
        for n in lengths:
            x = np.hstack([rng.normal(scale=0.3, size=(n, FEATURE_DIM)), rng.normal(scale=0.05, size=(n, PATH_SHAPE_DIM))])
            x[:, 3:6] = rng.uniform(-2.0 * FAST_TURN_RAD_S, 2.0 * FAST_TURN_RAD_S, (n, 3))  # the palm turns fast
            out.append((x.astype(np.float32), (np.tanh(x[:, FEATURE_DIM:FEATURE_DIM + 6] * 10.0) * 0.3).astype(np.float32)))
        return out
    context, target = pieces([30, 25, 28, 26, 22, 27]), pieces([20])[0][0]
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(context))
    keys, values, z, _ = one.encode_context(x_c, y_c, mask)
    assert float(one.blend_choice(keys)[0]) > 0.0  # the kernel read
    assert float(one.inner.switch_figures(one._inner_keys(keys))[0]) > 0.5  # the ridge cannot read them
    kernel_file = load_policy(build_path_shape_policy(CORE, tmp_path / "kernel.pt"))
    kernel_keys, kernel_values, kernel_z, _ = kernel_file.encode_context(x_c, y_c, mask)
    assert torch.equal(kernel_file.blend_choice(kernel_keys), one.blend_choice(keys))
    np.testing.assert_allclose(_stepped(one, target, keys, values, z, read=True),
                               _stepped(kernel_file, target, kernel_keys, kernel_values, kernel_z, read=True), atol=1e-6)
