"""Training, export and evaluation end to end on a tiny generated dataset (a few steps each)."""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest
import torch

from rtcohand_drake.learning.export import load_policy

pytestmark = pytest.mark.slow

BIN = pathlib.Path(sys.executable).parent


def _run(*args, env=None):
    run = subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, env=env)
    return run


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "tiny.h5"
    run = _run("rtcohand_drake.data.generate", "--out", str(path), "--users", "3", "--seed", "1")
    assert run.returncode == 0, run.stderr
    return path


TRAIN_ARGS = ["--steps", "3", "--batch-size", "4", "--validate-every", "2", "--validation-episodes", "4",
              "--threads", "1", "--quiet"]


@pytest.fixture(scope="module")
def trained(tiny_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    paths = {}
    for model in ("cchp", "ranp", "lstm"):
        run = _run("rtcohand_drake.train", "--data", str(tiny_data), "--out", str(out / model), "--model", model,
                   *TRAIN_ARGS)
        assert run.returncode == 0, run.stderr
        paths[model] = out / model / "checkpoint.pt"
    run = _run("rtcohand_drake.train", "--data", str(tiny_data), "--out", str(out / "fixed"), "--model", "cchp",
               "--tf-schedule", "fixed:0.9", "--seed", "1", *TRAIN_ARGS)
    assert run.returncode == 0, run.stderr
    paths["fixed"] = out / "fixed" / "checkpoint.pt"
    return paths


def test_each_model_trains_and_writes_its_outputs(trained):
    for model in ("cchp", "ranp", "lstm"):
        folder = trained[model].parent
        assert (folder / "training_curve.png").stat().st_size > 0
        history = json.loads((folder / "history.json").read_text())
        assert history["step"][-1] == 3
        payload = torch.load(trained[model], weights_only=True)
        assert payload["kind"] == model and payload["train_config"]["model"] == model
        assert payload["meta"]["samples_per_s"] > 0


def test_export_and_reload(trained, tmp_path):
    out = tmp_path / "policy.pt"
    run = _run("rtcohand_drake.export", "--checkpoint", str(trained["cchp"]), "--out", str(out))
    assert run.returncode == 0, run.stderr
    policy = load_policy(out)
    keys, values, z_mu, z_sigma = policy.encode_context(torch.zeros(1, 8, 36), torch.zeros(1, 8, 6),
                                                        torch.ones(1, 8, dtype=torch.bool))
    mean, std, h, c, att = policy.step(torch.zeros(36), torch.zeros(6), torch.zeros(policy.hidden_size),
                                       torch.zeros(policy.hidden_size), keys, values, z_mu)
    assert torch.isfinite(mean).all() and att.shape == (8,)
    run = _run("rtcohand_drake.export", "--checkpoint", str(trained["ranp"]), "--out", str(tmp_path / "r.pt"))
    assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1


def test_evaluate_writes_the_six_settings(tiny_data, trained, tmp_path):
    run = _run("rtcohand_drake.evaluate", "--data", str(tiny_data), "--checkpoint", str(trained["cchp"]),
               str(trained["fixed"]), str(trained["ranp"]), str(trained["lstm"]), "--out", str(tmp_path),
               "--noise-sweep", "--spectrum", "--attention", "--max-episodes", "6")
    assert run.returncode == 0, run.stderr
    results = json.loads((tmp_path / "results.json").read_text())
    assert set(results["models"]) == {"CCHP", "CCHP p_TF=0.9", "RANP", "Dummy LSTM"}
    for entry in results["models"].values():
        for setting in ("D+U+", "D+U-", "D-U+", "D-U-", "Unseen", "Noisy"):
            cell = entry["settings"][setting]
            assert "mse" in cell and "elbo_loss" in cell and "mse_std" in cell
        assert entry["settings"]["D+U+"]["mse"] > 0
    assert len(results["noise_sweep"]["levels"]) == 11
    for name in ("results.md", "noise_sweep.png", "spectrum.png", "attention.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_bad_inputs_are_one_line_errors(tiny_data, trained, tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"junk")
    not_h5 = tmp_path / "bad.h5"
    not_h5.write_bytes(b"junk")
    cases = [
        ("rtcohand_drake.evaluate", "--data", str(tiny_data), "--checkpoint", str(bad), "--out", str(tmp_path / "e")),
        ("rtcohand_drake.evaluate", "--data", str(not_h5), "--checkpoint", str(trained["cchp"]), "--out", str(tmp_path / "e")),
        ("rtcohand_drake.train", "--data", str(not_h5), "--out", str(tmp_path / "t"), "--steps", "1"),
    ]
    for args in cases:
        run = _run(*args)
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 2 and len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
        assert ("bad.pt" in lines[0]) or ("bad.h5" in lines[0])


@pytest.mark.skipif(shutil.which("torchrun", path=str(BIN)) is None, reason="torchrun not installed")
def test_torchrun_two_processes_on_gloo(tiny_data, tmp_path):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    run = subprocess.run([str(BIN / "torchrun"), "--nproc_per_node", "2", "--master_port", "29533", "-m",
                          "rtcohand_drake.train", "--data", str(tiny_data), "--out", str(tmp_path), "--steps", "3",
                          "--batch-size", "4", "--validate-every", "2", "--validation-episodes", "4", "--quiet"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    payload = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    assert payload["meta"]["world_size"] == 2 and payload["step"] == 3


def test_init_from_a_checkpoint(tiny_data, trained, tmp_path):
    """--init-from starts from a checkpoint's weights (with --lr 0 they come out unchanged); a
    checkpoint of another model kind is a one-line error."""
    from rtcohand_drake.learning.checkpoint import load_checkpoint

    args = ("rtcohand_drake.train", "--data", str(tiny_data), "--model", "cchp", "--lr", "0", *TRAIN_ARGS)
    run = _run(*args, "--out", str(tmp_path / "warm"), "--init-from", str(trained["cchp"]))
    assert run.returncode == 0, run.stderr
    source, _ = load_checkpoint(trained["cchp"])
    warm, _ = load_checkpoint(tmp_path / "warm" / "checkpoint.pt")
    for name, value in source.state_dict().items():
        assert torch.equal(value, warm.state_dict()[name]), name
    run = _run(*args, "--out", str(tmp_path / "bad"), "--init-from", str(trained["ranp"]))
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and "ranp" in lines[0], run.stderr


def test_init_from_takes_an_exported_policy(trained, tmp_path):
    """`--init-from` starts from an exported CCHP policy's weights as from a checkpoint's."""
    from rtcohand_drake.learning.checkpoint import build_model, load_checkpoint
    from rtcohand_drake.learning.export import cchp_from_policy
    from rtcohand_drake.learning.train import init_from_checkpoint

    policy = tmp_path / "policy.pt"
    run = _run("rtcohand_drake.export", "--checkpoint", str(trained["cchp"]), "--out", str(policy))
    assert run.returncode == 0, run.stderr
    source, payload = load_checkpoint(trained["cchp"])
    fresh = build_model("cchp", payload["model_config"])
    init_from_checkpoint(fresh, str(policy))
    rebuilt, _ = cchp_from_policy(policy)
    for key, value in rebuilt.state_dict().items():
        if not key.startswith("normalizer."):
            assert torch.equal(fresh.state_dict()[key], value), key
    for key, value in source.state_dict().items():  # and those are the checkpoint's own weights
        if not key.startswith("normalizer.") and key in fresh.state_dict():
            assert torch.equal(fresh.state_dict()[key], value), key
