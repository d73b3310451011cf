"""Recorded people: the SHREC'17 importer, the Person evaluation setting and the per-person references.

The tests write their own small skeleton files in the dataset's layout; the dataset itself never
enters the repository.
"""

import json
import pathlib
import subprocess
import sys

import h5py
import numpy as np
import pytest
import torch

from rtcohand_drake.data import import_shrec17 as shrec
from rtcohand_drake.data.dataset import read_dataset
from rtcohand_drake.data.sampling import evaluation_episodes
from rtcohand_drake.learning.knn_reference import KnnReference
from rtcohand_drake.learning.ridge_reference import RidgeReference
from rtcohand_drake.learning.train import load_clips

ROOT = pathlib.Path(__file__).resolve().parents[1]
SUBJECTS = (3, 5)
REPS = 3


def _hand() -> np.ndarray:
    """A right hand of 22 joints (wrist, palm centre, then thumb, index .. pinky base to tip), camera frame."""
    joints = [[0.0, 0.0, 0.0], [0.0, 0.05, 0.0]]
    for f, x in enumerate((-0.04, -0.02, 0.0, 0.02, 0.04)):
        for j in range(4):
            joints.append([x * (1.0 + 0.3 * j) - (0.03 if f == 0 else 0.0), 0.08 + 0.025 * j, -0.01 * j])
    return np.asarray(joints) + np.array([0.3, -0.3, 0.45])


def _stroke(variant: tuple[int, int], essai: int, n: int) -> np.ndarray:
    """(n, 22, 3): the hand strokes out and back along the variant's own direction (camera frame)."""
    direction = np.random.default_rng(list(variant)).normal(size=3)
    direction /= np.linalg.norm(direction)
    s = 0.12 * np.sin(np.pi * np.linspace(0.0, 1.0, n)) ** 2 * (1.0 + 0.05 * essai)
    return _hand()[None] + s[:, None, None] * direction


def write_tree(root: pathlib.Path, subjects=SUBJECTS, reps=REPS, n_frames=40, jitter_m=0.0) -> pathlib.Path:
    rows = []
    rng = np.random.default_rng(9)
    for s in subjects:
        for g in range(1, 15):
            for f in (1, 2):
                for e in range(1, reps + 1):
                    folder = root / f"gesture_{g}" / f"finger_{f}" / f"subject_{s}" / f"essai_{e}"
                    folder.mkdir(parents=True)
                    frames = (_stroke((g, f), e, n_frames) + rng.normal(scale=jitter_m, size=(n_frames, 22, 3))
                              ).reshape(n_frames, -1)
                    np.savetxt(folder / "skeletons_world.txt", frames, fmt="%.6f")
                    rows.append(f"{g} {f} {s} {e} {g} {g + 14 * (f - 1)} {n_frames}")
    (root / "train_gestures.txt").write_text("\n".join(rows) + "\n")
    return root


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    return write_tree(tmp_path_factory.mktemp("shrec17"))


@pytest.fixture(scope="module")
def natural(tree, tmp_path_factory):
    out = tmp_path_factory.mktemp("imported") / "natural.h5"
    shrec.import_shrec17(tree, out, "natural", progress=False)
    return out


def _run(*args):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True)


def test_import_writes_each_persons_commands_in_the_user_frame(tree, natural):
    clips = read_dataset(natural)
    assert sorted({c.user for c in clips}) == ["s03", "s05"]
    own = [c for c in clips if c.user == "s03"]
    assert len(own) == 12 * REPS
    # The last repetition of each variant is held out; the rest is the person's context.
    assert sorted(c.clip_id for c in own if c.split == "test") == sorted(
        f"g{g:02d}f{f}e{REPS:02d}" for g, f in shrec.NATURAL_MAP.values())
    with h5py.File(natural) as f:
        cmap = json.loads(f["users/s03"].attrs["command_map"])
        meta = json.loads(f.attrs["import"])
    assert cmap["Tx+"] == "G7F2" and meta["mapping"] == "natural" and meta["rest_s"] == 0.5
    # Swipe right (G7, whole hand) commands Tx+; its keypoints are the file's, palm joint dropped, in U.
    clip = next(c for c in own if c.clip_id == "g07f2e01")
    raw = np.loadtxt(tree / "gesture_7/finger_2/subject_3/essai_1/skeletons_world.txt").reshape(-1, 22, 3)
    rest = 15  # 0.5 s at 30 fps
    kp = clip.keypoints[rest:-rest]
    in_u = np.stack([raw[..., 0], -raw[..., 2], raw[..., 1]], -1)  # X = x, Y = -z, Z = y
    np.testing.assert_allclose(kp, np.concatenate([in_u[:, :1], in_u[:, 2:]], 1), atol=1e-6)
    assert np.all(clip.keypoints[:rest] == clip.keypoints[rest]) and np.all(clip.keypoints[-rest:] == clip.keypoints[-rest - 1])
    # Labels: zero at rest, the command's magnitude mid-gesture, ramped at the ends.
    y = clip.object_velocity
    assert list(clip.active_dims) == [0]
    assert np.all(y[:rest] == 0) and np.all(y[-rest:] == 0) and np.all(y[:, 1:] == 0)
    assert y[rest + 20, 0] == pytest.approx(shrec.TRANSLATION_M_S)
    assert 0 < y[rest, 0] < y[rest + 3, 0] < y[rest + 6, 0] == pytest.approx(shrec.TRANSLATION_M_S)
    turn = next(c for c in own if c.clip_id == "g06f1e01")  # rotation CCW, one finger: Rz+
    assert list(turn.active_dims) == [5] and turn.object_velocity[rest + 20, 5] == pytest.approx(shrec.ROTATION_RAD_S)


def test_whole_hand_map_makes_every_command_with_the_whole_hand(tree, tmp_path):
    out = tmp_path / "whole.h5"
    shrec.import_shrec17(tree, out, "whole-hand", progress=False)
    # The map as the issue of record states it: swipes right/left/up/down, expand/grab, rotation CCW/CW,
    # tap/pinch, swipe V/+ (G = 7, 8, 9, 10, 3, 1, 6, 5, 2, 4, 13, 12), all with the whole hand (F = 2).
    expected = {"Tx+": 7, "Tx-": 8, "Tz+": 9, "Tz-": 10, "Ty+": 3, "Ty-": 1, "Rz+": 6, "Rz-": 5,
                "Rx+": 2, "Rx-": 4, "Ry+": 13, "Ry-": 12}
    with h5py.File(out) as f:
        cmap = json.loads(f["users/s03"].attrs["command_map"])
        meta = json.loads(f.attrs["import"])
    assert meta["mapping"] == "whole-hand"
    assert cmap == {c: f"G{g}F2" for c, g in expected.items()}
    own = [c for c in read_dataset(out) if c.user == "s03"]
    swipe_v = next(c for c in own if c.clip_id == "g13f2e01")
    assert list(swipe_v.active_dims) == [4] and swipe_v.object_velocity[15 + 20, 4] == pytest.approx(shrec.ROTATION_RAD_S)
    assert not any(c.clip_id[3:5] == "f1" for c in own)  # nothing made with one finger
    run = _run("rtcohand_drake.data.import_shrec17", "--root", str(tree), "--out", str(tmp_path / "x.h5"),
               "--mapping", "whole-hand", "--subjects", "3")
    assert run.returncode == 0 and "whole-hand map" in run.stdout


def test_held_out_holds_out_the_last_repetitions_and_keeps_the_first_as_context(tree, tmp_path):
    out = tmp_path / "two.h5"
    run = _run("rtcohand_drake.data.import_shrec17", "--root", str(tree), "--out", str(out),
               "--mapping", "whole-hand", "--subjects", "3", "--held-out", "2")
    assert run.returncode == 0, run.stderr
    own = [c for c in read_dataset(out) if c.user == "s03"]
    by_variant: dict[str, dict[int, str]] = {}
    for c in own:
        by_variant.setdefault(c.clip_id[:5], {})[int(c.clip_id[6:])] = c.split
    assert len(by_variant) == 12
    assert all(splits == {1: "train", 2: "test", 3: "test"} for splits in by_variant.values())
    # More than the repetitions there are: the first still stays context.
    shrec.import_shrec17(tree, tmp_path / "all.h5", "whole-hand", subjects=[3], progress=False, held_out=REPS + 2)
    every = [c for c in read_dataset(tmp_path / "all.h5") if c.user == "s03"]
    assert {int(c.clip_id[6:]) for c in every if c.split == "train"} == {1}
    with h5py.File(tmp_path / "all.h5") as f:
        assert "last 5 repetitions" in json.loads(f.attrs["import"])["held_out"]
    bad = _run("rtcohand_drake.data.import_shrec17", "--root", str(tree), "--out", str(tmp_path / "x.h5"),
               "--held-out", "0")
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "--held-out" in bad.stderr


def test_rest_noise_rests_the_hand_with_the_persons_own_jitter(tmp_path):
    """--rest-noise: each held frame is the held one plus successive offsets of the person's own
    jitter where their hand hardly moves (`rest_noise_of`: `hand_features.slow_noise` over their mapped
    sequences); without it the rest is exactly still."""
    tree = write_tree(tmp_path / "shrec17", subjects=(3,), reps=2, jitter_m=0.002)
    still, noisy = tmp_path / "still.h5", tmp_path / "noisy.h5"
    shrec.import_shrec17(tree, still, "natural", progress=False)
    shrec.import_shrec17(tree, noisy, "natural", progress=False, rest_noise=True)
    with h5py.File(noisy) as f:
        assert "jitter" in json.loads(f.attrs["import"])["rest"]
    mapped = [q for q in shrec.find_sequences(tree) if q.variant in set(shrec.NATURAL_MAP.values())]
    pool = shrec.rest_noise_of(shrec.to_user_frame(shrec.read_skeletons(q.path)) for q in mapped)
    assert len(pool) > 10 and np.abs(pool).max() > 1e-4
    flat = pool.reshape(len(pool), -1)
    rest = 15
    for a, b in zip(read_dataset(still), read_dataset(noisy)):
        assert a.clip_id == b.clip_id and np.array_equal(a.object_velocity, b.object_velocity)
        np.testing.assert_array_equal(a.keypoints[rest:-rest], b.keypoints[rest:-rest])  # the gesture as it was
        assert np.all(a.keypoints[:rest] == a.keypoints[rest])  # still without the option
        for held, frames in ((a.keypoints[rest], b.keypoints[:rest]), (a.keypoints[-rest - 1], b.keypoints[-rest:])):
            offsets = (frames - held).reshape(rest, -1)
            # Successive rows of the pool from some start.
            runs = [i for i in range(len(pool))
                    if np.abs(flat[(i + np.arange(rest)) % len(pool)] - offsets).max() < 1e-5]
            assert runs, "the rest is not successive rows of the person's jitter"
    run = _run("rtcohand_drake.data.import_shrec17", "--root", str(tree), "--out", str(tmp_path / "x.h5"), "--rest-noise")
    assert run.returncode == 0, run.stderr


def test_axis_map_is_a_proper_rotation():
    assert np.linalg.det(shrec.R_UC) == pytest.approx(1.0)
    # A hand moving toward the camera (depth falling) moves forward in U, away from the person.
    assert (shrec.R_UC @ np.array([0.0, 0.0, -1.0]))[1] == 1.0


def test_custom_maps_draw_twelve_variants_per_person(tree, tmp_path):
    out = tmp_path / "custom.h5"
    run = _run("rtcohand_drake.data.import_shrec17", "--root", str(tree), "--out", str(out), "--mapping", "custom",
               "--seed", "4")
    assert run.returncode == 0, run.stderr
    with h5py.File(out) as f:
        maps = {u: json.loads(f[f"users/{u}"].attrs["command_map"]) for u in f["users"]}
    for m in maps.values():
        assert sorted(m) == sorted(shrec.COMMAND_NAMES) and len(set(m.values())) == 12
    assert maps["s03"] != maps["s05"]  # each person their own set
    again = shrec.command_map("custom", [(g, f) for g in range(1, 15) for f in (1, 2)], 3, 4)
    assert {c: f"G{g}F{f}" for c, (g, f) in again.items()} == maps["s03"]


@pytest.mark.parametrize("damage, expected", [
    (lambda p: p.write_text(" ".join(["0.1"] * 65 + ["oops"]) + "\n"), "line 1 is not numbers"),
    (lambda p: p.write_text(" ".join(["0.1"] * 63) + "\n"), "line 1 has 63 values, expected 66"),
    (lambda p: p.write_text(""), "0 frames"),
])
def test_bad_skeleton_files_are_one_line_errors(tmp_path, damage, expected):
    root = write_tree(tmp_path / "shrec", subjects=(2,), reps=2, n_frames=6)
    bad = root / "gesture_7/finger_2/subject_2/essai_1/skeletons_world.txt"
    damage(bad)
    run = _run("rtcohand_drake.data.import_shrec17", "--root", str(root), "--out", str(tmp_path / "o.h5"))
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and expected in lines[0]
    assert not (tmp_path / "o.h5").exists()


def test_missing_folder_and_subject_are_one_line_errors(tree, tmp_path):
    for args, expected in ((["--root", str(tmp_path / "nowhere")], "no such folder"),
                           (["--root", str(tree), "--subjects", "9"], "no sequences of subject(s) 9")):
        run = _run("rtcohand_drake.data.import_shrec17", *args, "--out", str(tmp_path / "o.h5"))
        assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1 and expected in run.stderr


def test_person_setting_reads_held_out_clips_with_the_persons_own_context(natural):
    clips = load_clips(str(natural), 10.0)
    episodes = evaluation_episodes(clips, "Person", 0)
    assert len(episodes) == 2 * 12
    by_name = {c.name: c for c in clips}
    for e in episodes:
        assert e.target.split == "test"
        own_train = [c for c in clips if c.user == e.target.user and c.split == "train"]
        assert len(e.context) == len(own_train) == 12 * (REPS - 1)
        assert all(any(np.array_equal(x, c.features) for c in own_train) for x, _ in e.context)
    assert all(by_name[e.target.name] is e.target for e in episodes)


def _policy_means_by_the_contract(module, episode) -> np.ndarray:
    """The exported policy played as the contract says: one context clip a row (each encoded from a zero
    state), the context encoded once, the policy's own mean fed back, z = z_mu."""
    longest = max(len(x) for x, _ in episode.context)
    n = len(episode.context)
    x_c, y_c, mask = np.zeros((n, longest, 36), np.float32), np.zeros((n, longest, 6), np.float32), np.zeros((n, longest), bool)
    for i, (x, y) in enumerate(episode.context):
        x_c[i, :len(x)], y_c[i, :len(x)], mask[i, :len(x)] = x, y, True
    keys, values, z, _ = module.encode_context(torch.from_numpy(x_c), torch.from_numpy(y_c), torch.from_numpy(mask))
    h = c = torch.zeros(int(module.hidden_size))
    y = torch.zeros(6)
    out = []
    for x in episode.target_features:
        y, _, h, c, _ = module.step(torch.from_numpy(np.ascontiguousarray(x)), y, h, c, keys, values, z)
        out.append(y.numpy().astype(np.float64))
    return np.array(out)


def _labels_at_policy_rate(clip, rate_hz=10.0) -> np.ndarray:
    t = np.arange(clip.num_frames) / clip.fps
    tq = np.arange(int(np.floor(t[-1] * rate_hz + 1e-6)) + 1) / rate_hz
    return np.stack([np.interp(tq, t, clip.object_velocity[:, d]) for d in range(6)], 1)


def test_evaluate_person_setting_share_matches_an_independent_calculation(natural, tmp_path):
    model = ROOT / "models" / "cchp_default.pt"
    run = _run("rtcohand_drake.evaluate", "--data", str(natural), "--checkpoint", str(model), "--names", "shipped",
               "--settings", "Person", "--out", str(tmp_path), "--knn", "6", "3", "--ridge", "4", "50")
    assert run.returncode == 0, run.stderr
    results = json.loads((tmp_path / "results.json").read_text())
    module = torch.jit.load(str(model))
    episodes = evaluation_episodes(load_clips(str(natural), 10.0), "Person", 0)
    raw = {c.name: c for c in read_dataset(natural)}
    errors, zeros, ridge, knn = [], [], [], []
    with torch.no_grad():
        for e in episodes:
            y = _labels_at_policy_rate(raw[e.target.name])
            assert y.shape == e.target.labels.shape
            errors.append(np.mean((y - _policy_means_by_the_contract(module, e)) ** 2))
            zeros.append(np.mean(y ** 2))
            ridge.append(np.mean((y - RidgeReference(4, 50.0).fit(e.context).predict(e.target.features)) ** 2))
            knn.append(np.mean((y - KnnReference(6, 3).fit(e.context).predict(e.target.features)) ** 2))
    ref = results["reference"]
    assert ref["zero_twist_mse"]["Person"] == pytest.approx(np.mean(zeros), rel=1e-5)
    share = results["models"]["shipped"]["settings"]["Person"]["mse"] / ref["zero_twist_mse"]["Person"]
    assert share == pytest.approx(np.mean(errors) / np.mean(zeros), rel=2e-3)
    assert ref["ridge_mse"]["Person"] == pytest.approx(np.mean(ridge), rel=1e-5)
    assert ref["knn_mse"]["Person"] == pytest.approx(np.mean(knn), rel=1e-5)
    assert ref["knn"] == {"window": 6, "k": 3} and ref["ridge"] == {"window": 4, "lam": 50.0}
    # The kernel read of the path and shape, written out here: the keypoints at the policy's times, now
    # and 4, 8, 12, 16 steps before about the centre now, standardised, a Gaussian kernel ridge.
    kernel = []
    for e in episodes:
        def shape(name):
            clip = raw[name]
            t = np.arange(clip.num_frames) / clip.fps
            tq = np.arange(int(np.floor(t[-1] * 10.0 + 1e-6)) + 1) / 10.0
            kp = np.stack([np.interp(tq, t, clip.keypoints[:, i // 3, i % 3]) for i in range(63)], 1).reshape(-1, 21, 3)
            n = len(kp)
            return np.concatenate([(kp[np.maximum(np.arange(n) - lag, 0)] - kp.mean(1, keepdims=True)).reshape(n, -1)
                                   for lag in (0, 4, 8, 12, 16)], 1)
        names = [c.name for c in read_dataset(natural) if c.user == e.target.user and c.split == "train"]
        s = np.concatenate([shape(n) for n in names])
        y_c = np.concatenate([_labels_at_policy_rate(raw[n]) for n in names])
        mean, spread = s.mean(0), s.std(0) + 1e-6
        s = (s - mean) / spread
        d = np.sqrt(((s[:, None] - s[None]) ** 2).sum(-1))
        width = 0.5 * np.median(d[d > 0])
        w = np.linalg.solve(np.exp(-d ** 2 / (2 * width ** 2)) + 0.3 * np.eye(len(s)), y_c - y_c.mean(0))
        q = (shape(e.target.name) - mean) / spread
        near = np.sqrt(((q[:, None] - s[None]) ** 2).sum(-1))
        pred = y_c.mean(0) + np.exp(-near ** 2 / (2 * width ** 2)) @ w
        kernel.append(np.mean((_labels_at_policy_rate(raw[e.target.name]) - pred) ** 2))
    assert ref["kernel_mse"]["Person"] == pytest.approx(np.mean(kernel), rel=2e-3)  # its features are float32
    assert ref["kernel"] == {"bandwidth": 0.5, "lam": 0.3}
    assert "share of commanding zero twist" in (tmp_path / "results.md").read_text()


def test_knn_reference_reads_a_stroke_with_a_return_the_right_way():
    """A stroke out and back along +X labelled Tx+, and one along -X labelled Tx-: over the stroke the
    window's net motion is near zero, so a read of the last second's mean velocity cannot tell them
    apart, but the shape of the motion can."""
    def stroke(sign, n=20, rest=5):
        v = np.zeros((n + 2 * rest, 36), np.float32)
        v[rest:rest + n, 0] = sign * 0.2 * np.sin(2 * np.pi * np.arange(n) / n)  # out, then back
        y = np.zeros((n + 2 * rest, 6), np.float32)
        y[rest:rest + n, 0] = sign * 0.12
        return v, y
    context = [stroke(1), stroke(-1), stroke(1), stroke(-1)]
    for sign in (1, -1):
        x, y = stroke(sign)
        pred = KnnReference(window=20, k=2).fit(context).predict(x)
        active = y[:, 0] != 0
        assert np.sign(pred[active, 0].mean()) == sign
        assert np.mean((pred - y) ** 2) < 0.2 * np.mean(y.astype(float) ** 2)


def test_context_reading_split_protocol_reads_the_held_out_clips(natural):
    run = _run("rtcohand_drake.context_reading", "--context-file", str(natural), "--context-user", "s05",
               "--protocol", "split", "--knn", "6", "3")
    assert run.returncode == 0, run.stderr
    out = run.stdout
    assert "the 12 clips of split 'test' read with the 24 of split 'train'" in out
    rows = [line for line in out.splitlines() if line.startswith("| T") or line.startswith("| R")]
    assert len(rows) == 12 and all(line.split("|")[2].strip() == "1" for line in rows)
    assert "nearest neighbours (window 6, k 3)" in out and "of commanding zero twist" in out
    # A file with no test clips cannot be read this way: one line, status 2.
    run = _run("rtcohand_drake.context_reading", "--user", "u10", "--protocol", "split")
    assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1 and "split" in run.stderr


def test_path_and_shape_ridge_matches_independent_limits(natural, load_script):
    """The benchmark's ridge and kernel reads of the hand's path and shape: under a huge lambda each
    falls to each person's mean context label (computed here on its own), and a moderate lambda reads
    the written gestures better than that."""
    limits = load_script("benchmarks/real_people_limits.py")
    clips = [c for c in read_dataset(natural) if c.object_velocity is not None]
    error = zero = 0.0
    for user in sorted({c.user for c in clips}):
        context = [_labels_at_policy_rate(c) for c in clips if c.user == user and c.split == "train"]
        mean = np.concatenate(context).mean(0)
        for c in clips:
            if c.user == user and c.split == "test":
                y = _labels_at_policy_rate(c)
                error += np.mean((mean - y) ** 2)
                zero += np.mean(y ** 2)
    assert zero > 0
    expected = error / zero
    assert limits.trajectory_ridge_share(natural, lam=1e12) == pytest.approx(expected, rel=1e-4)
    assert limits.trajectory_ridge_share(natural, lam=1.0) < expected
    # The kernel read likewise falls to the mean under a huge lambda, and reads better with a small one.
    assert limits.trajectory_kernel_share(natural, lam=1e12) == pytest.approx(expected, rel=1e-4)
    assert limits.trajectory_kernel_share(natural) < expected
