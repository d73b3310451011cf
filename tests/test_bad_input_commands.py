"""The other commands meet bad input as the run does: one line naming the flag or file, status 2, before
any work is done (a recording session, a study's runs, an evaluation) that the error would throw away."""

import pytest

from rtcohand_drake.errors import run_cli


def _one_line(capsys, main, argv, *fragments):
    status = run_cli(main, argv, prog="test")
    err = capsys.readouterr().err
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.mark.parametrize("args, fragment", [
    (["--user", "a/b"], "--user 'a/b'"),
    (["--user", ""], "--user ''"),
    (["--out", "{tmp}"], "is a folder"),
    (["--out", "{tmp}/nowhere/r.h5"], "does not exist"),
    (["--seed", "-1"], "--seed: must be >= 0"),
    (["--model", "{tmp}/text.pt"], "not a TorchScript policy"),
    (["--scenario", "{tmp}/empty.yaml", "--no-check"], "the file is empty"),
])
def test_record_checks_what_it_writes_and_reads_before_the_session(tmp_path, capsys, args, fragment):
    from rtcohand_drake.record import main

    (tmp_path / "text.pt").write_text("not a policy")
    (tmp_path / "empty.yaml").write_text("")
    argv = ["--out", str(tmp_path / "r.h5"), "--user", "ME", "--simulated-user", "u10", "--no-meshcat"]
    argv += [a.replace("{tmp}", str(tmp_path)) for a in args]
    _one_line(capsys, main, argv, fragment)
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("args, fragment", [
    (["--populations", "200", "--workers", "-2"], "--workers/--jobs: must be >= 0"),
    (["--populations", "200", "--cap", "-5"], "--cap: must be a positive number"),
    (["--populations", "5-2"], "a range from low to high"),
    (["--populations", "abc"], "expected a seed such as 100"),
    (["--populations", "200", "--address", "notanaddress"], "tcp://HOST:PORT"),
    (["--populations", "200", "--users", "zz"], "--users: unknown zz"),
    (["--populations", "200", "--model", "{tmp}/text.pt"], "not a TorchScript policy"),
    (["--summarise-only", "--bootstrap", "0"], "--bootstrap must be at least 1"),
    (["--summarise-only"], "no run log of these runs"),
])
def test_a_study_checks_its_flags_before_any_run(tmp_path, capsys, args, fragment):
    from rtcohand_drake.analysis.study import main

    (tmp_path / "text.pt").write_text("not a policy")
    _one_line(capsys, main, ["--out", str(tmp_path / "study")] + [a.replace("{tmp}", str(tmp_path)) for a in args],
              fragment)


def test_evaluate_and_the_reading_check_refuse_bad_reference_settings_first(tmp_path, capsys):
    from rtcohand_drake.analysis.context_reading import main as reading
    from rtcohand_drake.learning.evaluate import main as evaluate

    base = ["--data", str(tmp_path / "none.h5"), "--checkpoint", "models/cchp_default.pt"]
    _one_line(capsys, evaluate, base + ["--out", str(tmp_path / "ev"), "--ridge", "-1", "5"], "--ridge WINDOW LAMBDA")
    _one_line(capsys, evaluate, base + ["--out", str(tmp_path / "ev"), "--knn", "0", "0"], "--knn WINDOW K")
    (tmp_path / "file").write_text("")
    _one_line(capsys, evaluate, base + ["--out", str(tmp_path / "file")], "is a file; give a folder")
    _one_line(capsys, reading, ["--user", "u10", "--rate-hz", "0"], "--rate-hz: must be a positive number")
    _one_line(capsys, reading, ["--user", "u10", "--knn", "-1", "0"], "--knn WINDOW K")


def test_importing_a_folder_with_no_usable_gesture_writes_nothing(tmp_path, capsys):
    from rtcohand_drake.data.import_shrec17 import main

    sequence = tmp_path / "gesture_1" / "finger_1" / "subject_1" / "essai_1"
    sequence.mkdir(parents=True)
    (sequence / "skeletons_world.txt").write_text("garbage x y\n")
    (tmp_path / "informations_troncage_sequences.txt").write_text("1 2 3\n")
    _one_line(capsys, main, ["--root", str(tmp_path), "--out", str(tmp_path / "out.h5")], "nothing written")
    assert not (tmp_path / "out.h5").exists()
    _one_line(capsys, main, ["--root", str(tmp_path), "--out", str(tmp_path / "out.h5"), "--mapping", "foo"],
              "--mapping: invalid choice")


def test_a_policy_file_builder_refuses_a_folder_for_its_output_and_leaves_nothing(tmp_path, capsys):
    from rtcohand_drake.learning.ridge_blend_policy import main

    _one_line(capsys, main, ["--policy", "models/cchp_default.pt", "--out", str(tmp_path)], "is a folder")
    assert list(tmp_path.parent.glob(tmp_path.name + ".tmp")) == []
