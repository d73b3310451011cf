"""The held-out reading check of a user's gestures (rtcohand_drake.analysis.context_reading)."""

import numpy as np
import pytest
import torch

from rtcohand_drake.analysis import context_reading as cr
from rtcohand_drake.data.dataset import write_dataset
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.errors import run_cli


class ScaledEcho:
    """A stand-in policy module: its mean is `gain` times the first six features.

    It records the features of every context it is given, so a test can check
    that a clip is never played with itself in the context.
    """

    hidden_size = 4

    def __init__(self, gain):
        self.gain = gain
        self.contexts = []

    def encode_context(self, x_c, y_c, mask):
        self.contexts.append(x_c[mask].numpy().copy())
        return torch.zeros(int(mask.sum()), 2), y_c[mask], torch.zeros(3), torch.ones(3)

    def step(self, x_t, y_prev, h, c, keys, values, z):
        mean = self.gain * x_t[:6]
        return mean, torch.ones(6), h, c, torch.zeros(keys.shape[0])


def _clips(n=12, length=30, seed=0):
    """Clips whose first six features equal their labels; clip i moves dimension i % 6 with sign (-1)^(i // 6)."""
    rng = np.random.default_rng(seed)
    clips = []
    for i in range(n):
        d, sign = i % 6, (-1) ** (i // 6)
        labels = np.zeros((length, 6))
        labels[5:25, d] = sign * (0.1 + 0.02 * rng.random()) * np.sin(np.linspace(0, np.pi, 20))
        features = np.zeros((length, 36))
        features[:, :6] = labels
        features[:, 6:] = rng.normal(0, 0.01, (length, 30))
        clips.append(cr.LabelledClip(f"c{i}", features, labels, (d,)))
    return clips


@pytest.mark.parametrize("gain", [1.0, 0.3, -0.5])
def test_reading_gain_is_the_predicted_share_of_the_label(gain):
    readings = cr.held_out_readings(ScaledEcho(gain), _clips(), folds=3)
    assert len(readings) == 12
    assert np.allclose([r.gain for r in readings], gain, atol=1e-5)
    rows = cr.motion_table(readings)
    assert [name for name, *_ in rows] == [cr.motion_name(d, s) for d in range(6) for s in (1, -1)]
    assert {word for *_, word in rows} == {cr.verdict(gain)}


def test_verdicts():
    assert cr.verdict(0.8) == "reads" and cr.verdict(0.3) == "weak"
    assert cr.verdict(0.1) == "poor" and cr.verdict(-0.9) == "poor"


def test_a_clip_is_never_in_its_own_context():
    clips = _clips()
    module = ScaledEcho(1.0)
    cr.held_out_readings(module, clips, folds=4)
    assert len(module.contexts) == 4
    for f, context in enumerate(module.contexts):
        for i, clip in enumerate(clips):
            inside = any(np.allclose(context[k:k + len(clip.features)], clip.features)
                         for k in range(0, len(context) - len(clip.features) + 1, len(clip.features)))
            assert inside == (i % 4 != f)


def test_cli_prints_a_row_per_motion(tmp_path, capsys):
    from rtcohand_drake.learning.export import script_policy
    from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig

    torch.manual_seed(0)
    model = Cchp(CchpConfig(hidden_size=16, aggregate_sizes=[16], latent_trunk_sizes=[16],
                            latent_dim=4, key_size=8, output_hidden=[16]))
    policy = tmp_path / "policy.pt"
    torch.jit.save(script_policy(model), str(policy))
    data = tmp_path / "one_user.h5"
    write_dataset(data, list(generate_population(GeneratorConfig(), n_users=1, seed=2)))
    status = run_cli(cr.main, ["--context-file", str(data), "--model", str(policy), "--folds", "3"])
    out = capsys.readouterr().out
    assert status == 0
    rows = [line for line in out.splitlines() if line.startswith("| ") and line[2:4] in cr.MOTION_NAMES]
    assert len(rows) == 12
    assert "median reading gain" in out
    poor = [line.split("|")[1].strip() for line in rows if "| poor |" in line]
    assert poor  # an untrained policy reads some motions poorly, and is told what to do about them
    # Each poor motion gets one piece of advice: held motion when a read of the motion's shape (the
    # nearest-neighbour reference, the last column) reads it, a different gesture when nothing does.
    cells = {line.split("|")[1].strip(): line.split("|") for line in rows}
    by_shape = [m for m in poor if float(cells[m][-2]) >= cr.READS]
    unread = [m for m in poor if m not in by_shape]
    if unread:
        assert ("poorly read: " + ", ".join(unread) + ". ") in out and "Record a different gesture" in out
    if by_shape:
        assert ("read by its shape but not by the policy: " + ", ".join(by_shape) + ". ") in out
    assert ("poorly read" in out) == bool(unread) and ("read by its shape" in out) == bool(by_shape)


def test_cli_gives_no_advice_when_every_motion_reads(capsys):
    # The shipped policy reads every motion of the benchmark population's u10 (weakest: 0.76).
    status = run_cli(cr.main, ["--user", "u10"])
    captured = capsys.readouterr()
    out = captured.out
    assert status == 0 and "| poor |" not in out and "poorly read" not in out
    # A long check is not silent: its progress bar, on stderr, reaches every read (policy and references).
    assert "reading u10's clips" in captured.err and "100%" in captured.err
    assert "reading u10's clips" not in out


def test_every_option_has_help():
    """`--help` explains every option of the reading check and of the camera calibration."""
    from rtcohand_drake.vision import calibrate

    for parser in (cr.make_parser(), calibrate.make_parser()):
        bare = [a.option_strings for a in parser._actions if not a.help]
        assert not bare, (parser.prog, bare)


@pytest.mark.parametrize("argv, expected", [
    (["--folds", "1", "--user", "u10"], "--folds must be >= 2"),
    ([], "give either --context-file"),
    (["--user", "u99"], "unknown user 'u99'"),
])
def test_cli_bad_input_is_one_line(argv, expected, capsys):
    assert run_cli(cr.main, argv) == 2
    err = capsys.readouterr().err.strip()
    assert expected in err and len(err.splitlines()) == 1


def test_the_check_reads_the_output_the_run_gives():
    """With correction weight w the output is r + w (mean - r); the stand-in's read r is zero."""
    readings = cr.held_out_readings(ScaledEcho(0.8), _clips(), folds=3, correction_weight=0.25)
    assert np.allclose([r.gain for r in readings], 0.2, atol=1e-5)


def test_confusions_name_a_gesture_read_along_another_motion():
    """`confusions`: the median over a gesture's clips of the read along each other motion, as a share of
    the person's command on that axis, while the gesture is made; named from CONFUSED_SHARE up."""
    clips = _clips()  # clip i: dimension i % 6, sign (-1)^(i // 6)
    size = np.max([np.abs(c.labels).max(0) for c in clips], axis=0)  # the person's command on each axis
    means = [np.zeros_like(c.labels) for c in clips]
    means[0][:, 1] = 0.6 * size[1]  # Tx+ read along Ty+ by 0.6 of its size
    means[6][:, 1] = 0.1 * size[1]  # Tx- barely
    means[8][:, 3] = -0.4 * size[3]  # Tz- along Rx-
    found = cr.confusions(clips, means)
    assert [(a, b) for a, b, _ in found] == [("Tx+", "Ty+"), ("Tz-", "Rx-")]
    assert [round(v, 3) for _, _, v in found] == [0.6, 0.4]
    assert cr.confusions(clips, means, share=0.5) == [("Tx+", "Ty+", pytest.approx(0.6))]
    assert cr.confusions(clips, [None] * len(clips)) == []  # nothing played, nothing named


def test_the_check_names_two_commands_given_the_same_gesture(tmp_path, capsys):
    """A person whose Ty+ clips are exactly their Tx+ clips (the same gesture for two commands): the file
    for real hands reads each along the other, and the check says so; their own session does not."""
    import dataclasses

    from rtcohand_drake.data.dataset import read_dataset
    from rtcohand_drake.record import main as record

    session = tmp_path / "me.h5"
    assert record(["--out", str(session), "--user", "ME", "--simulated-user", "u11", "--no-meshcat", "--no-check",
                   "--only", "Tx+,Ty+,Rz+"]) == 0
    clips = read_dataset(session)
    cr.check(["--context-file", str(session), "--context-user", "ME", "--no-progress"])
    assert "read as another motion" not in capsys.readouterr().out
    swap = [1, 0, 2, 3, 4, 5]  # Tx's label moved to Ty
    twins = [c for c in clips if not c.clip_id.endswith("Ty+")]
    twins += [dataclasses.replace(c, clip_id=f"{90 + k}_Ty+", active_dims=np.array([1]),
                                  object_velocity=c.object_velocity[:, swap])
              for k, c in enumerate(c for c in clips if c.clip_id.endswith("Tx+"))]
    write_dataset(tmp_path / "same.h5", twins)
    cr.check(["--context-file", str(tmp_path / "same.h5"), "--context-user", "ME", "--no-progress"])
    text = capsys.readouterr().out
    assert "read as another motion: Tx+ as Ty+" in text and "Ty+ as Tx+" in text
