"""How well the policy read a replayed stream: the figures, the run log's pairing of labels and
outputs, and `run --split test` printing them."""

import dataclasses as dc
import subprocess
import sys

import numpy as np
import pytest
import torch

from rtcohand_drake.analysis.replay_read import ReplayRead, log_read, read_figures
from rtcohand_drake.data.dataset import load_policy_clips, read_dataset, write_dataset
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.data.sampling import pack_context


@pytest.fixture(scope="module")
def split_file(tmp_path_factory):
    """Two generated people; each one's last 3 clips marked held out (`split = test`)."""
    clips = list(generate_population(GeneratorConfig(), n_users=2, seed=3))
    out = []
    for user in sorted({c.user for c in clips}):
        mine = sorted((c for c in clips if c.user == user), key=lambda c: c.clip_id)
        out += [dc.replace(c, split="test" if i >= len(mine) - 3 else "train") for i, c in enumerate(mine)]
    path = tmp_path_factory.mktemp("data") / "split.h5"
    write_dataset(path, out)
    return path


@pytest.fixture(scope="module")
def policy_file(small_policy_file):
    return small_policy_file


def test_the_figures_against_a_calculation_written_out():
    full = np.array([0.12, 0.12, 0.12, 0.6, 0.6, 0.6])
    labels = np.zeros((14, 6))
    labels[1:4, 0] = 0.12  # a gesture along +Tx, steps 1-3
    labels[11:13, 5] = -0.6  # another along -Rz, steps 11-12
    out = np.zeros((14, 6))
    out[1, 0] = -0.03  # against the gesture: -0.25 of a full command
    out[2, 0] = 0.10
    out[3, 0] = -0.02  # against it by less than a fifth: not counted
    out[9, 3] = 0.13  # at rest, over a fifth of a full command (0.12 rad/s)
    out[10, 1] = 0.02  # at rest, under a fifth
    out[11, 5] = -0.5
    out[12, 4] = 0.7  # another axis: not against this gesture's
    figures = read_figures(out, labels, rate_hz=10.0)
    # Rest: no label, from 0.5 s (5 steps) after the last label: steps 9 and 10 (3 is the last label,
    # 9 - 3 = 6 > 5), and step 13 (13 - 12 = 1) is not.
    assert (figures.rest_steps, figures.rest_moving) == (2, 1)
    assert (figures.gesture_steps, figures.against) == (5, 1)
    expected = ((out - labels) ** 2).sum() / (labels ** 2).sum()
    assert figures.share == pytest.approx(expected)
    assert full[0] == 0.12  # the scale the thresholds above were written for
    pooled = ReplayRead.pooled([figures, figures])
    assert pooled.share == pytest.approx(expected) and pooled.rest_steps == 4 and pooled.against == 2


def test_a_replay_logs_its_labels_and_the_log_gives_the_offline_figures(split_file, policy_file):
    """Through the whole diagram, the log pairs each played frame's label with the box's read of that
    frame: the figures equal those of the module stepped offline on the same stream."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.diagram import build_run_diagram, collect_run_log
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.systems.gestures.replay import ReplayGestureSource
    from rtcohand_drake.systems.policy import CchpPolicy

    clips = load_policy_clips(split_file)
    user = clips[0].user
    played = [c for c in clips if c.user == user][-2:]
    pieces = [(c.features, c.labels) for c in clips if c.user == user and c not in played][:6]
    scenario = load_scenario("inspection")
    policy = CchpPolicy(policy_file, pieces, 10.0, seed=1, rest_release=False)
    source = ReplayGestureSource(played, 10.0)
    run = build_run_diagram(scenario, source=source, policy=policy)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(source.end_time)
    log = collect_run_log(run, simulator.get_context(), scenario)
    stream_labels = np.concatenate([c.labels for c in played])
    assert log.gesture_intended.shape[1] == 6
    np.testing.assert_allclose(log.gesture_intended[:len(stream_labels)], stream_labels, atol=1e-6)

    module = load_policy(policy_file)
    x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(pieces))
    keys, values, _, _ = module.encode_context(x_c, y_c, mask)
    z = torch.from_numpy(policy.sample_z(0)).float()
    h, c, y = torch.zeros(int(module.hidden_size)), torch.zeros(int(module.hidden_size)), torch.zeros(6)
    offline = []
    with torch.no_grad():
        for x in np.nan_to_num(np.concatenate([p.features for p in played])):
            y, _, h, c, _ = module.step(torch.from_numpy(x).float(), y, h, c, keys, values, z)
            offline.append(y.numpy().copy())
    offline = np.array(offline)
    read = log_read(log)
    n = len(offline)  # every frame's read is in the log: its samples run from 0 to the stream's end
    assert len(log.gesture_time) == n + 1
    want = read_figures(offline[:n], stream_labels[:n], 10.0)
    assert read.zero == pytest.approx(want.zero, rel=1e-5)
    assert read.error == pytest.approx(want.error, rel=1e-3)
    assert (read.rest_steps, read.rest_moving, read.gesture_steps, read.against) == (
        want.rest_steps, want.rest_moving, want.gesture_steps, want.against)
    # Paired one period off, the figures would differ: the pairing is what makes them the read's.
    shifted = read_figures(offline[1:], stream_labels[:n - 1], 10.0)
    assert abs(shifted.error - read.error) > 1e-3 * read.error


def test_run_split_test_replays_the_held_out_clips_and_prints_the_read(tmp_path, split_file, policy_file):
    user = read_dataset(split_file)[0].user
    run = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--no-meshcat", "--realtime-rate", "0",
                          "--gesture-file", str(split_file), "--clip", user, "--split", "test",
                          "--model", str(policy_file), "--log", str(tmp_path / "run.h5")],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    line = next(l for l in run.stdout.splitlines() if l.startswith("read of the replayed labels"))
    share = float(line.split(": ", 1)[1].split(" of zero twist")[0])
    from rtcohand_drake.run_log import read_run_log

    log = read_run_log(tmp_path / "run.h5")
    test_frames = sum(len(c) for c in load_policy_clips(split_file) if c.user == user and c.split == "test")
    assert len(log.gesture_time) == pytest.approx(test_frames, abs=2)  # the 3 held-out clips, not all
    assert share == pytest.approx(log_read(log).share, abs=1e-3)
    # The module's command line pools several logs.
    cli = subprocess.run([sys.executable, "-m", "rtcohand_drake.analysis.replay_read", str(tmp_path / "run.h5"),
                          str(tmp_path / "run.h5"), "--json", str(tmp_path / "read.json")],
                         capture_output=True, text=True, timeout=300)
    assert cli.returncode == 0 and "pooled over 2 runs" in cli.stdout, cli.stderr
    bad = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--split", "test", "--no-meshcat"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--split goes with --gesture-source replay" in bad.stderr
    none = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--no-meshcat", "--gesture-file",
                           str(split_file), "--clip", user + "/nope", "--split", "test", "--model", str(policy_file)],
                          capture_output=True, text=True, timeout=300)
    assert none.returncode == 2 and len(none.stderr.strip().splitlines()) == 1
