"""The recorder: a simulated person's session is a contract-valid dataset file with every one-motion clip."""

import json
import pathlib
from dataclasses import replace as dc_replace

import h5py
import numpy as np
import pytest

from rtcohand_drake.data.dataset import read_dataset
from rtcohand_drake.errors import InputError
from rtcohand_drake.record import ONE_MOTIONS, TWO_MOTIONS, Protocol, cue_twist, main, motion_name, parse_only


def test_simulated_session_writes_a_contract_valid_file(tmp_path, capsys):
    out = tmp_path / "me.h5"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check",
                 "--repeats", "1"]) == 0
    clips = read_dataset(out)  # the reader validates the whole file against the contract
    assert len(clips) == len(ONE_MOTIONS) + len(TWO_MOTIONS) and {c.user for c in clips} == {"ME"}
    one = [c for c in clips if len(c.active_dims) == 1]
    seen = set()
    for clip in one:
        d = int(clip.active_dims[0])
        label = clip.object_velocity[:, d]
        sign = 1 if label[np.argmax(np.abs(label))] > 0 else -1
        seen.add((d, sign))
        assert clip.clip_id.endswith(motion_name(((d, sign),)))
        # The label is on the cued dimension alone, and the hand was seen.
        others = np.delete(clip.object_velocity, d, axis=1)
        assert np.abs(others).max() < 1e-6 < np.abs(label).max()
        assert np.isfinite(clip.keypoints).all(axis=(1, 2)).mean() > 0.8
    assert seen == {m[0] for m in ONE_MOTIONS}  # all 12: both signs of each dimension
    with h5py.File(out) as f:
        assert f.attrs["label_source"] == "cue"
        assert f.attrs["label_delay_s"] == pytest.approx(Protocol().response_delay_s + Protocol().label_lag_s)
    # The same seed records the same session.
    again = tmp_path / "again.h5"
    main(["--out", str(again), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check",
          "--only", "Tx+", "--repeats", "1"])
    assert np.array_equal(read_dataset(again)[0].keypoints, clips[0].keypoints, equal_nan=True)


def test_reading_check_names_the_motions(tmp_path, capsys, monkeypatch):
    """The closing hint records again exactly the motions the check read below its threshold, and
    says how to read both files as one context; with none, it says there is nothing to record."""
    from rtcohand_drake.analysis import context_reading

    out = tmp_path / "few.h5"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Tx-,Rz+,Rz-", "--repeats", "1"]) == 0
    text = capsys.readouterr().out
    assert "| Tx+ | 1 |" in text and "| Rz- | 1 |" in text
    assert "policy cchp_path_shape.pt" in text  # a recording is a real person's: the file for real hands
    gains = {line.split("|")[1].strip(): float(line.split("|")[3]) for line in text.splitlines()
             if line.startswith("| ") and line[2:4] in context_reading.MOTION_NAMES}
    # A stricter threshold, between the weakest and the best read motion, makes some of them weak.
    threshold = (min(gains.values()) + max(gains.values())) / 2
    monkeypatch.setattr(context_reading, "READS", threshold)
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Tx-,Rz+,Rz-", "--repeats", "1"]) == 0
    text = capsys.readouterr().out
    weak = [m for m in ("Tx+", "Tx-", "Rz+", "Rz-") if gains[m] < threshold]
    assert 0 < len(weak) < 4
    again = tmp_path / "few_again.h5"
    assert f"read below half their size: {', '.join(weak)}" in text
    hint = (f"python -m rtcohand_drake.record --out {again} --user ME --simulated-user u11 --population-seed 0 "
            f"--seed 0 --no-meshcat --style hold --only {','.join(weak)} --repeats 1")
    assert hint in text
    # The printed command records them again as printed (the same person, source and settings).
    import shlex

    assert main(shlex.split(hint.split("python -m rtcohand_drake.record ", 1)[1]) + ["--no-check"]) == 0
    assert {c.clip_id.split("_", 1)[1] for c in read_dataset(again)} == set(weak)
    assert f"--context-file {out} {again} --context-user ME" in text
    monkeypatch.setattr(context_reading, "READS", -10.0)
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Rz-"]) == 0
    text = capsys.readouterr().out
    assert "nothing to record again" in text and "--only" not in text.split("reading check:")[1]


def test_reading_check_uses_the_policy_file_given(tmp_path, capsys):
    """`--model` reads the new clips with that file: here the file for real hands, on its wider input."""
    out = tmp_path / "few.h5"
    model = pathlib.Path(__file__).resolve().parents[1] / "models" / "cchp_path_shape.pt"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Tx-,Rz+,Rz-", "--model", str(model), "--repeats", "1"]) == 0
    text = capsys.readouterr().out
    assert "policy cchp_path_shape.pt" in text and "| Rz- | 1 |" in text


def test_a_session_records_each_gesture_three_times_in_rounds(tmp_path):
    """By default the 12 one-motion clips come three times over, in rounds, each a gesture of its own
    (the simulated person draws each afresh), then the two-motion clips once; `--repeats` and `--only`
    go together, and the file records the repeats."""
    out = tmp_path / "me.h5"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check"]) == 0
    clips = read_dataset(out)
    names = [c.clip_id.split("_", 1)[1] for c in clips]
    one = [motion_name(m) for m in ONE_MOTIONS]
    assert names == one * 3 + [motion_name(m) for m in TWO_MOTIONS]
    assert len({c.clip_id for c in clips}) == len(clips)
    for k in range(len(one)):
        first, second = clips[k].keypoints, clips[k + len(one)].keypoints
        assert first.shape != second.shape or not np.array_equal(first, second, equal_nan=True)
    with h5py.File(out) as f:
        assert json.loads(f.attrs["recorder"])["repeats"] == 3
    two = tmp_path / "two.h5"
    assert main(["--out", str(two), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check",
                 "--only", "Tx+,Rz-,Tx+Ty+", "--repeats", "2"]) == 0
    assert [c.clip_id for c in read_dataset(two)] == ["00_Tx+", "01_Rz-", "02_Tx+", "03_Rz-", "04_Tx+Ty+"]
    for bad in ("0", "11"):
        with pytest.raises(InputError, match="--repeats must be from 1 to 10"):
            main(["--out", str(tmp_path / "x.h5"), "--user", "ME", "--simulated-user", "u10", "--repeats", bad])


def test_the_check_names_gestures_with_fewer_than_three_recordings(tmp_path, capsys):
    """The reading check names the one-motion gestures recorded fewer than `RECORDINGS` times (the
    recorder's default rounds) and the command that records them again."""
    from rtcohand_drake.analysis.context_reading import RECORDINGS
    from rtcohand_drake.record import DEFAULT_REPEATS

    assert RECORDINGS == DEFAULT_REPEATS
    one = tmp_path / "one.h5"
    assert main(["--out", str(one), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Rz-,Tx+Ty+", "--repeats", "1"]) == 0
    text = capsys.readouterr().out
    assert "fewer than 3 recordings of: Tx+ (1), Rz- (1)." in text  # the two-motion clip is not counted
    assert "python -m rtcohand_drake.record --only Tx+,Rz-)" in text
    three = tmp_path / "three.h5"
    assert main(["--out", str(three), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Rz-"]) == 0
    assert "fewer than" not in capsys.readouterr().out


def test_cue_and_only():
    t = np.linspace(0.0, Protocol().clip_s, 121)
    cue = cue_twist(((0, 1), (5, -1)), t, Protocol())
    assert cue[0, 0] == 0 and cue[-1, 0] == 0 and cue[:, 0].max() == pytest.approx(Protocol().cue_speed_m_s)
    assert cue[:, 5].min() == pytest.approx(-Protocol().cue_rate_rad_s) and np.all(cue[:, 1:5] == 0)
    assert parse_only("Tx+,Rz-,Tx+Ty-") == [((0, 1),), ((5, -1),), ((0, 1), (1, -1))]
    for bad in ("Tq+", "Tx", "Tx+Tx-", "Tx+Ty+Tz+"):
        with pytest.raises(InputError, match="--only"):
            parse_only(bad)


def test_bad_arguments_are_one_line(tmp_path):
    with pytest.raises(InputError, match="unknown user"):
        main(["--out", str(tmp_path / "x.h5"), "--user", "ME", "--simulated-user", "u99", "--no-check"])
    with pytest.raises(InputError, match="does not exist"):
        main(["--out", str(tmp_path / "no" / "x.h5"), "--user", "ME", "--simulated-user", "u10"])
    with pytest.raises(InputError, match="command line"):
        main(["--out", str(tmp_path / "x.h5"), "--user", "ME"])  # no gesture source


class _FakeCamera:
    """A tracker with a hand that waves and a marked object moving at a known twist, 30 frames a second."""

    fps = 30.0
    V, W = np.array([0.05, 0.0, -0.02]), np.array([0.0, 0.0, 0.3])

    def __init__(self):
        self._t = None

    def latest(self, now_s):
        from rtcohand_drake.vision.drawn_hand import open_hand_U

        self._t = np.floor(now_s * self.fps + 1e-6) / self.fps
        return open_hand_U((0.02 * np.sin(3 * self._t), 0.2, 0.0)), self._t

    def marker(self):
        import cv2

        if int(round(self._t * self.fps)) % 7 == 3:
            return None  # the marker is missed now and then
        return cv2.Rodrigues(self.W * self._t)[0], self.V * self._t


@pytest.mark.parametrize("labels", ["cue", "aruco"])
def test_tracked_session_labels(labels, capsys):
    from pydrake.geometry import Meshcat, MeshcatParams

    from rtcohand_drake.record import CueView, record_tracked

    protocol = Protocol(countdown_s=1.0, clip_s=3.0)
    view = CueView(Meshcat(MeshcatParams(host="localhost", port=0))) if labels == "cue" else None
    clips = record_tracked(_FakeCamera(), [((0, 1),), ((5, -1),)], protocol, "ME", live=False, labels=labels,
                           view=view)
    assert [c.clip_id for c in clips] == ["00_Tx+", "01_Rz-"]
    prompts = [line for line in capsys.readouterr().out.splitlines() if "gesture while" in line]
    assert [line.split(":")[0].strip() for line in prompts] == ["clip 1 of 2, Tx+", "clip 2 of 2, Rz-"]
    for clip in clips:
        assert clip.num_frames == 90 and clip.fps == pytest.approx(30.0)
        assert np.all(np.isfinite(clip.keypoints)) and np.all(np.isfinite(clip.object_velocity))
    if labels == "cue":
        assert clips[0].object_velocity[:, 0].max() == pytest.approx(protocol.cue_speed_m_s, rel=1e-3)
        assert clips[1].object_velocity[:, 5].min() == pytest.approx(-protocol.cue_rate_rad_s, rel=1e-3)
    else:  # the marked object's own twist, whatever the cue
        middle = clips[0].object_velocity[10:-10]
        assert np.allclose(middle, np.r_[_FakeCamera.V, _FakeCamera.W], atol=1e-6)


def test_aruco_labels_need_a_camera(tmp_path):
    with pytest.raises(InputError, match="--labels aruco needs"):
        main(["--out", str(tmp_path / "x.h5"), "--user", "ME", "--simulated-user", "u10", "--labels", "aruco"])


def test_a_stroke_session_cues_strokes_and_says_so(tmp_path, capsys):
    import json

    from rtcohand_drake.record import protocol_for, record_tracked

    stroke = protocol_for("stroke")
    # The stroke cue: faster, and moving for 1.2 s rather than 2.5 s; the shifted labels end in the clip.
    t = np.arange(0.0, stroke.clip_s, 0.01)
    cue = cue_twist(((0, 1),), t, stroke)
    moving = t[np.abs(cue[:, 0]) > 0.5 * stroke.cue_speed_m_s]
    assert cue[:, 0].max() == pytest.approx(0.12) and moving[-1] - moving[0] == pytest.approx(1.0, abs=0.05)
    assert stroke.cue_end_s + stroke.response_delay_s + stroke.label_lag_s < stroke.clip_s
    hold = Protocol()
    moving_hold = t[np.abs(cue_twist(((0, 1),), t, hold)[:, 0]) > 0.5 * hold.cue_speed_m_s]
    assert moving_hold[-1] - moving_hold[0] > 1.5 * (moving[-1] - moving[0])
    # A tracked stroke session prompts a stroke and labels each clip with the stroke cue.
    clips = record_tracked(_FakeCamera(), [((5, -1),)], dc_replace(stroke, countdown_s=1.0), "ME", live=False)
    assert "make one stroke" in capsys.readouterr().out
    assert clips[0].object_velocity[:, 5].min() == pytest.approx(-0.6, rel=1e-3)
    # A simulated session: the same person strokes, and the file records the style.
    out = tmp_path / "strokes.h5"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check",
                 "--style", "stroke", "--only", "Tx+"]) == 0
    held = tmp_path / "held.h5"
    main(["--out", str(held), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check", "--only", "Tx+"])
    with h5py.File(out) as f:
        assert json.loads(f.attrs["recorder"])["protocol"]["style"] == "stroke"
    # The same person's hand, stroking: it comes partly back, so its net move along x is shorter than
    # when the motion is held (and both go the cued way).
    a, b = read_dataset(out)[0], read_dataset(held)[0]
    net = lambda c: float(np.nanmean(c.keypoints[-5:, 0, 0]) - np.nanmean(c.keypoints[:5, 0, 0]))  # noqa: E731
    assert 0 < net(a) < 0.6 * net(b)


def test_the_reading_check_advises_by_style(tmp_path, capsys, monkeypatch):
    from rtcohand_drake.analysis import context_reading

    for style in ("stroke", "hold"):
        out = tmp_path / f"{style}.h5"
        main(["--out", str(out), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check",
              "--style", style, "--only", "Tx+,Tx-,Rz+,Rz-"])
        assert context_reading.recording_style(out) == style
    # The advice for a motion read by its shape alone depends on the style recorded: the verdicts
    # are forced here (a motion read by the nearest-neighbour reference and not by the policy).
    monkeypatch.setattr(context_reading, "WEAK", 2.0)  # every motion counts as poorly read by the policy
    monkeypatch.setattr(context_reading, "READS", -10.0)  # and as read by its shape
    for style, expected in (("stroke", "--style hold --only"), ("hold", "rather than stroking out and back")):
        context_reading.main(["--context-file", str(tmp_path / f"{style}.h5"), "--context-user", "ME"])
        assert expected in capsys.readouterr().out
    with pytest.raises(InputError, match="--style"):
        main(["--out", str(tmp_path / "x.h5"), "--user", "ME", "--simulated-user", "u10", "--style", "wave"])
