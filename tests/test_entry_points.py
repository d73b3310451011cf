"""The run CLI rejects every kind of bad input file with exit status 2 and one line naming the file."""

import subprocess
import sys

import h5py
import numpy as np
import pytest

from rtcohand_drake.data.dataset import write_dataset
from rtcohand_drake.data.population import GeneratorConfig, generate_population


@pytest.fixture(scope="module")
def good_data(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "one_user.h5"
    write_dataset(path, [c for c in generate_population(GeneratorConfig(), n_users=1, seed=1)][:6])
    return path


def _run(*args):
    return subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--no-meshcat", "--realtime-rate", "0",
                           "--duration", "1", *args], capture_output=True, text=True, timeout=300)


def _assert_one_line(proc, *fragments):
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def _corrupt_copies(tmp_path, good):
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    not_hdf5 = tmp_path / "text.h5"
    not_hdf5.write_text("this is not HDF5\n")
    wrong_format = tmp_path / "wrong_format.h5"
    wrong_format.write_bytes(good.read_bytes())
    with h5py.File(wrong_format, "r+") as f:
        f.attrs["format"] = "something-else"
    wrong_shape = tmp_path / "wrong_shape.h5"
    wrong_shape.write_bytes(good.read_bytes())
    with h5py.File(wrong_shape, "r+") as f:
        user = next(iter(f["users"]))
        clip = next(iter(f["users"][user]["clips"]))
        group = f["users"][user]["clips"][clip]
        del group["keypoints"]
        group.create_dataset("keypoints", data=np.zeros((5, 20, 3), np.float32))
    return {"truncated": truncated, "not_hdf5": not_hdf5, "wrong_format": wrong_format,
            "wrong_shape": wrong_shape, "missing": tmp_path / "nowhere.h5"}


@pytest.mark.parametrize("kind", ["truncated", "not_hdf5", "wrong_format", "wrong_shape", "missing"])
def test_corrupt_gesture_file(tmp_path, good_data, kind):
    bad = _corrupt_copies(tmp_path, good_data)[kind]
    _assert_one_line(_run("--gesture-source", "replay", "--gesture-file", str(bad)), str(bad))


@pytest.mark.parametrize("kind", ["truncated", "wrong_format", "missing"])
def test_corrupt_context_file(tmp_path, good_data, kind):
    bad = _corrupt_copies(tmp_path, good_data)[kind]
    _assert_one_line(_run("--gesture-source", "replay", "--gesture-file", str(good_data),
                          "--context-file", str(bad)), str(bad))


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 not really a zip", b"plain text"])
def test_corrupt_model_file(tmp_path, good_data, content):
    bad = tmp_path / "policy.pt"
    bad.write_bytes(content)
    _assert_one_line(_run("--gesture-source", "replay", "--gesture-file", str(good_data), "--model", str(bad)),
                     str(bad))


def test_a_model_file_damaged_inside_its_weights_is_refused(tmp_path, good_data):
    """Bytes changed inside a weight tensor leave a readable archive that would load and run with wrong
    numbers; every entry's CRC-32 is checked first."""
    import pathlib
    import zipfile

    shipped = pathlib.Path(__file__).resolve().parents[1] / "models" / "cchp_default.pt"
    with zipfile.ZipFile(shipped) as archive:
        info = max(archive.infolist(), key=lambda i: i.file_size)  # the largest tensor
    data = bytearray(shipped.read_bytes())
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + 64
    data[start:start + 256] = bytes(256)
    bad = tmp_path / "damaged.pt"
    bad.write_bytes(bytes(data))
    _assert_one_line(_run("--gesture-source", "replay", "--gesture-file", str(good_data), "--model", str(bad)),
                     str(bad), "fails its checksum")


def test_unknown_clip_and_user(good_data):
    _assert_one_line(_run("--gesture-source", "replay", "--gesture-file", str(good_data), "--clip", "nobody/x"),
                     "nobody/x")


def test_replaying_all_of_a_persons_clips_says_how_to_give_a_context(good_data):
    with h5py.File(good_data) as f:
        user = sorted(f["users"].keys())[0]
    _assert_one_line(_run("--gesture-file", str(good_data), "--clip", user),
                     f"user {user!r} are being replayed", "--context-file")


def test_malformed_yaml(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("cell: {mold: [1, 2\n")
    _assert_one_line(_run("--scenario", str(path)), str(path), "malformed YAML")


@pytest.mark.parametrize("args, fragment", [
    (["--gesture-source", "replay"], "needs --gesture-file"),
    (["--context-user", "u0"], "--context-user goes with --context-file"),
    (["--gesture-source", "bogus"], "invalid choice"),
    (["--seed", "x"], "--seed: must be a whole number"),
    (["--seed", "-1"], "--seed: must be >= 0"),
    (["--gesture-source", "camera", "--camera", "-1"], "--camera: must be >= 0"),
    (["--gesture-source", "scripted", "--model", "models/cchp_default.pt"], "--model and --context-file go with"),
    (["--log", "tests"], "--log tests: is a folder"),
    (["--model", "tests"], "tests: a folder, not a policy file"),
    (["--gesture-source", "scripted", "--population-seed", "2"], "--population-seed goes with the synthetic"),
])
def test_bad_flags(args, fragment):
    _assert_one_line(_run(*args), fragment)


def test_no_meshcat_and_no_wait_are_not_exclusive():
    """Both flags are accepted together, and no usage line (argparse's, the module's, the docs')
    shows them as alternatives."""
    import re
    from pathlib import Path

    import rtcohand_drake.run as run

    args = run.make_parser().parse_args(["--no-meshcat", "--no-wait"])
    assert args.no_meshcat and args.no_wait
    exclusive = re.compile(r"--no-meshcat\s*\|\s*--no-wait|--no-wait\s*\|\s*--no-meshcat")
    repo = Path(__file__).resolve().parents[1]
    usages = {"argparse": run.make_parser().format_usage(), "run.py": run.__doc__,
              **{p.name: p.read_text() for p in [repo / "README.md", *(repo / "docs").glob("*.md")]}}
    assert not [name for name, text in usages.items() if exclusive.search(text)]


def test_missing_motions_warning_says_how_to_add_them_and_a_second_file_does(tmp_path, capsys):
    """A context lacking motions names them and the command that records them into a further file;
    that file given after the first (`--context-file A.h5 B.h5`) completes the context."""
    from rtcohand_drake.run import main

    clips = [c for c in generate_population(GeneratorConfig(), n_users=1, seed=1)]
    first, more = tmp_path / "first.h5", tmp_path / "more.h5"
    write_dataset(first, [c for c in clips if list(c.active_dims) == [0]])
    write_dataset(more, [c for c in clips if list(c.active_dims) != [0]])
    common = ["--no-meshcat", "--duration", "0.2", "--realtime-rate", "0"]
    assert main([*common, "--context-file", str(first)]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if "holds no example" in line]
    assert len(warning) == 1 and "Tx+" not in warning[0].split("record them")[0]
    assert f"--user {clips[0].user} --only Ty+," in warning[0] and "add MORE.h5 to --context-file" in warning[0]
    assert main([*common, "--context-file", str(first), str(more)]) == 0
    assert "holds no example" not in capsys.readouterr().err


def test_a_context_whose_hand_is_lost_in_its_gestures_is_named_in_a_warning(tmp_path, good_data):
    """A context file whose clips never show the hand (NaN keypoints) gives features of no motion; the run
    still runs (the part does not move: safe), and says why in one warning line."""
    from rtcohand_drake.data.dataset import context_pieces, lost_hand_share

    lost = tmp_path / "lost.h5"
    lost.write_bytes(good_data.read_bytes())
    with h5py.File(lost, "r+") as f:
        user = next(iter(f["users"]))
        for clip in f["users"][user]["clips"].values():
            clip["keypoints"][...] = np.nan
    assert lost_hand_share(context_pieces([good_data], user, 10.0)[0]) < 0.1
    assert lost_hand_share(context_pieces([lost], user, 10.0)[0]) > 0.95
    proc = _run("--gesture-source", "replay", "--gesture-file", str(good_data), "--context-file", str(lost))
    warnings = [line for line in proc.stderr.splitlines() if "lose the hand" in line]
    assert proc.returncode == 0 and len(warnings) == 1, proc.stderr[-2000:]
