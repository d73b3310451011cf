"""The recorder: a simulated person's session is a contract-valid dataset file with every one-motion clip."""

import h5py
import numpy as np
import pytest

from rtcohand_drake.data.dataset import read_dataset
from rtcohand_drake.errors import InputError
from rtcohand_drake.record import ONE_MOTIONS, TWO_MOTIONS, Protocol, cue_twist, main, motion_name, parse_only


def test_simulated_session_writes_a_contract_valid_file(tmp_path, capsys):
    out = tmp_path / "me.h5"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u10", "--no-meshcat", "--no-check"]) == 0
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
          "--only", "Tx+"])
    assert np.array_equal(read_dataset(again)[0].keypoints, clips[0].keypoints, equal_nan=True)


def test_reading_check_names_the_motions(tmp_path, capsys):
    out = tmp_path / "few.h5"
    assert main(["--out", str(out), "--user", "ME", "--simulated-user", "u11", "--no-meshcat",
                 "--only", "Tx+,Tx-,Rz+,Rz-"]) == 0
    text = capsys.readouterr().out
    assert "| Tx+ | 1 |" in text and "| Rz- | 1 |" in text
    assert "read below half their size:" in text and "--only" in text


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
