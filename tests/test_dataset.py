"""Dataset file: round trip, validation, and one-line errors from the command lines."""

import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from rtcohand_drake.data.dataset import (
    DatasetError,
    load_policy_clips,
    read_dataset,
    write_dataset,
)
from rtcohand_drake.data.population import GeneratorConfig, generate_population


@pytest.fixture(scope="module")
def clips():
    return generate_population(GeneratorConfig(), n_users=2, seed=3)


@pytest.fixture(scope="module")
def good_file(tmp_path_factory, clips):
    path = tmp_path_factory.mktemp("data") / "good.h5"
    write_dataset(path, clips)
    return path


def _copy(src, dst):
    dst.write_bytes(src.read_bytes())
    return dst


def test_round_trip_identical(good_file, clips):
    back = read_dataset(good_file)
    assert len(back) == len(clips) == 144
    by_name = {c.name: c for c in back}
    for c in clips:
        b = by_name[c.name]
        assert (b.group, b.split, b.fps, b.description) == (c.group, c.split, c.fps, c.description)
        np.testing.assert_array_equal(b.active_dims, c.active_dims)
        np.testing.assert_array_equal(b.keypoints, c.keypoints)  # NaN frames compare equal
        np.testing.assert_array_equal(b.object_velocity, c.object_velocity)
        np.testing.assert_array_equal(b.object_pose, c.object_pose)
        assert b.keypoints.dtype == np.float32 and b.timestamps is None


def test_file_layout_follows_contract(good_file):
    with h5py.File(good_file, "r") as f:
        assert f.attrs["format"] == "rtcohand-gestures" and int(f.attrs["version"]) == 1
        user = f["users/u00"]
        assert user.attrs["group"] == "in-sample"
        clip = next(iter(user["clips"].values()))
        assert set(clip.attrs) >= {"fps", "active_dims", "split"}
        assert clip["keypoints"].dtype == np.float32 and clip["keypoints"].shape[1:] == (21, 3)
        assert clip["object_velocity"].shape[1] == 6 and clip["object_pose"].shape[1] == 7


def test_load_policy_clips(good_file):
    pcs = load_policy_clips(good_file, rate_hz=10.0)
    assert len(pcs) == 144
    for p in pcs:
        assert p.features.shape == (len(p), 36) and p.features.dtype == np.float32
        assert p.labels.shape == (len(p), 6) and p.valid.shape == (len(p),)
        assert np.isfinite(p.features).all()
        assert len(p) <= 51  # at most 5 s at 10 Hz


def test_optional_fields_and_timestamps(tmp_path, clips):
    c = clips[0]
    from dataclasses import replace

    ts = 100.0 + np.arange(c.num_frames) / c.fps
    bare = replace(c, object_velocity=None, object_pose=None, timestamps=ts, active_dims=np.zeros(0, np.int64),
                   split="none", clip_id="stream")
    path = tmp_path / "bare.h5"
    write_dataset(path, [bare])
    (back,) = read_dataset(path)
    assert back.object_velocity is None and back.active_dims.size == 0
    np.testing.assert_array_equal(back.timestamps, ts)
    (p,) = load_policy_clips(path)
    assert p.labels is None and p.features.shape[1] == 36


def _expect(path, *fragments):
    with pytest.raises(DatasetError) as info:
        read_dataset(path)
    text = str(info.value)
    assert "\n" not in text and text.startswith(str(path))
    for frag in fragments:
        assert frag in text, text
    return text


def test_truncated_file(tmp_path, good_file):
    data = good_file.read_bytes()
    bad = tmp_path / "truncated.h5"
    bad.write_bytes(data[: len(data) // 3])
    _expect(bad)


def test_not_hdf5_and_missing(tmp_path):
    bad = tmp_path / "text.h5"
    bad.write_text("hello")
    _expect(bad, "HDF5")
    _expect(tmp_path / "nope.h5", "no such file")


@pytest.mark.parametrize(
    "edit, fragments",
    [
        (lambda f: f.attrs.__setitem__("format", "something-else"), ["unknown format"]),
        (lambda f: f.attrs.__delitem__("format"), ["missing root attribute 'format'"]),
        (lambda f: f.attrs.__setitem__("version", 7), ["unknown version 7"]),
        (lambda f: f["users/u00"].attrs.__setitem__("group", "both"), ["user u00", "group"]),
        (lambda f: f["users/u00/clips/00_Tx-Ty-"].attrs.__delitem__("fps"), ["clip u00/00_Tx-Ty-", "missing attribute 'fps'"]),
        (lambda f: f["users/u00/clips/00_Tx-Ty-"].attrs.__delitem__("split"), ["clip u00/00_Tx-Ty-", "'split'"]),
        (lambda f: f["users/u00/clips/00_Tx-Ty-"].attrs.__setitem__("fps", 2.0), ["clip u00/00_Tx-Ty-", "fps"]),
        (lambda f: f["users/u00/clips/00_Tx-Ty-"].attrs.__setitem__("active_dims", [7]), ["active_dims"]),
        (lambda f: f["users/u00/clips/00_Tx-Ty-"].attrs.__setitem__("split", "val"), ["split"]),
        (lambda f: _replace(f, "users/u00/clips/00_Tx-Ty-/keypoints", np.zeros((10, 20, 3), np.float32)),
         ["clip u00/00_Tx-Ty-", "keypoints must have shape (N, 21, 3)"]),
        (lambda f: _replace(f, "users/u00/clips/00_Tx-Ty-/object_velocity", np.zeros((3, 6), np.float32)),
         ["clip u00/00_Tx-Ty-", "object_velocity must have shape"]),
        (lambda f: _poison(f, "users/u00/clips/00_Tx-Ty-/object_velocity"), ["non-finite"]),
        (lambda f: f.__delitem__("users/u00/clips/00_Tx-Ty-/keypoints"), ["missing dataset 'keypoints'"]),
        (lambda f: f.__delitem__("users"), ["missing group '/users'"]),
    ],
)
def test_contract_breaches_are_one_line_errors(tmp_path, good_file, edit, fragments):
    with h5py.File(good_file, "r") as f:
        assert "00_Tx-Ty-" in f["users/u00/clips"], "fixture clip name changed; update the test"
    bad = _copy(good_file, tmp_path / "bad.h5")
    with h5py.File(bad, "r+") as f:
        edit(f)
    _expect(bad, *fragments)


def _replace(f, key, data):
    del f[key]
    f[key] = data


def _poison(f, key):
    arr = f[key][()]
    arr[2, 1] = np.nan
    _replace(f, key, arr)


def test_write_is_atomic(tmp_path, clips):
    path = tmp_path / "out.h5"
    write_dataset(path, clips[:3])
    from dataclasses import replace

    broken = replace(clips[3], keypoints=np.zeros((5, 21, 2), np.float32))
    with pytest.raises(DatasetError):
        write_dataset(path, clips[:3] + [broken])
    assert len(read_dataset(path)) == 3  # the old file is intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.h5"]  # no temporary left


def _run(*args):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=120)


def test_plots_cli_on_corrupt_file_exits_2_one_line(tmp_path, good_file):
    bad = _copy(good_file, tmp_path / "bad.h5")
    with h5py.File(bad, "r+") as f:
        f.attrs["format"] = "wrong"
    res = _run("rtcohand_drake.data.plots", "--data", str(bad), "--clip", "u00/00_Tx-Ty-", "--out", str(tmp_path / "f.png"))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and "format" in lines[0]
    assert "Traceback" not in res.stderr
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(good_file.read_bytes()[:5000])
    res = _run("rtcohand_drake.data.plots", "--data", str(trunc), "--clip", "u00/00_Tx-Ty-", "--out", str(tmp_path / "f.png"))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and str(trunc) in res.stderr


def test_plots_cli_writes_png(tmp_path, good_file):
    out = tmp_path / "fig.png"
    res = _run("rtcohand_drake.data.plots", "--data", str(good_file), "--clip", "u00/00_Tx-Ty-", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = _run("rtcohand_drake.data.plots", "--data", str(good_file), "--clip", "u00/nope", "--out", str(out))
    assert res.returncode == 2 and "nope" in res.stderr and len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("args", [["--users", "0"], ["--users", "x"], ["--fps", "2"], []])
def test_generate_cli_bad_args_exit_2_one_line(tmp_path, args):
    res = _run("rtcohand_drake.data.generate", *(["--out", str(tmp_path / "x.h5")] if args else []), *args)
    assert res.returncode == 2
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr


def test_generate_cli_writes_readable_file(tmp_path):
    out = tmp_path / "one.h5"
    res = _run("rtcohand_drake.data.generate", "--out", str(out), "--users", "1", "--seed", "5")
    assert res.returncode == 0, res.stderr
    assert "user 1/1" in res.stdout
    clips = read_dataset(out)
    assert len(clips) == 72 and {c.group for c in clips} == {"in-sample"}
    with h5py.File(out, "r") as f:
        assert "generator" in f.attrs


def test_meshcat_animation_of_a_clip(clips):
    pytest.importorskip("pydrake")
    from pydrake.geometry import Meshcat, MeshcatParams

    from rtcohand_drake.data.meshcat_view import animate_clip

    meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
    anim = animate_clip(meshcat, clips[0], prefix="test_clip")
    assert anim.frames_per_second() == clips[0].fps
    assert meshcat.HasPath("test_clip/workpiece") and meshcat.HasPath("test_clip/hand/k20")


def test_missing_motions_names_what_a_context_holds_no_example_of():
    from rtcohand_drake.analysis.context_reading import builtin_clips
    from rtcohand_drake.data.dataset import missing_motions

    clips = builtin_clips("u10", 10.0)
    full = [(c.features, c.labels) for c in clips]
    assert missing_motions(full) == []
    # Leave out every clip that moves along -x or turns about +z: exactly those two are named.
    kept = [(c.features, c.labels) for c in clips
            if not ((c.labels[:, 0] < -0.01).any() or (c.labels[:, 5] > 0.05).any())]
    assert 0 < len(kept) < len(full)
    assert missing_motions(kept) == ["Tx-", "Rz+"]
    # Labels all zero (or not finite): every motion is missing.
    still = [(np.zeros((20, 36)), np.full((20, 6), np.nan))]
    assert len(missing_motions(still)) == 12


def test_dataset_and_run_log_get_the_usual_mode(tmp_path, clips):
    """Both atomic writers give their file 0666 less the umask, not mkstemp's private 0600."""
    import os
    import stat

    from rtcohand_drake.run_log import RunLog, write_run_log

    old = os.umask(0o022)
    try:
        write_dataset(tmp_path / "data.h5", clips[:2])
        write_run_log(tmp_path / "run.h5", RunLog(scenario="inspection"))
    finally:
        os.umask(old)
    for name in ("data.h5", "run.h5"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644, name


def test_context_user_error_says_the_list_of_users_is_cut(tmp_path):
    from rtcohand_drake.data.dataset import context_pieces
    from rtcohand_drake.errors import InputError

    many = generate_population(GeneratorConfig(), n_users=12, seed=3)
    path = tmp_path / "many.h5"
    first = {}
    for clip in many:  # two clips of each person are enough
        first.setdefault(clip.user, []).append(clip)
    write_dataset(path, [c for person in first.values() for c in person[:2]])
    with pytest.raises(InputError, match=r"holds 12 users.*, \.\.\. and 4 more\)$"):
        context_pieces(path, None, 10.0)
    with pytest.raises(InputError, match=r"has no labelled clips.*\(users: .*, \.\.\. and 4 more\)$"):
        context_pieces(path, "nobody", 10.0)


def test_context_from_several_files(tmp_path):
    """`--context-file A.h5 B.h5`: one user's clips of both files, read as one context; one file as before."""
    from rtcohand_drake.analysis.context_reading import clips_from_file
    from rtcohand_drake.data.dataset import context_pieces
    from rtcohand_drake.errors import InputError
    from rtcohand_drake.run import make_parser

    clips = generate_population(GeneratorConfig(), n_users=2, seed=4)
    me = [c for c in clips if c.user == clips[0].user]
    first, second, other = tmp_path / "first.h5", tmp_path / "second.h5", tmp_path / "other.h5"
    write_dataset(first, me[:5])
    write_dataset(second, me[5:8])
    write_dataset(other, [c for c in clips if c.user != me[0].user][:3])
    one, user = context_pieces(first, None, 10.0)
    both, same = context_pieces([first, second], None, 10.0)
    assert user == same == me[0].user and len(one) == 5 and len(both) == 8
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(one, both))  # the first file's clips come first
    assert len(clips_from_file([first, second], user, 10.0)[0]) == 8
    with pytest.raises(InputError, match=r"first\.h5 and .*other\.h5: hold 2 users; choose one"):
        context_pieces([first, other], None, 10.0)
    with pytest.raises(InputError, match=rf"other\.h5: user '{user}' has no labelled clips"):
        context_pieces([first, other], user, 10.0)
    # The command line takes one path as before, several after one flag, or the flag repeated.
    parse = lambda *a: make_parser().parse_args(list(a)).context_file  # noqa: E731
    assert parse("--context-file", "a.h5") == [Path("a.h5")]
    assert parse("--context-file", "a.h5", "b.h5") == parse("--context-file", "a.h5", "--context-file", "b.h5")
