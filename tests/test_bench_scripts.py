"""Benchmarks whose figures the docs quote: they measure what they say they measure."""

import json
import statistics
import subprocess
import sys
from pathlib import Path

from conftest import REPO


def test_bench_policy_box_times_each_file_with_its_own_context(tmp_path, load_script):
    """Both shipped files, a few periods: a figure per file and round, the first round left out of the
    median; the wide file's box is built with the hand's path and shape in its context (else it refuses)."""
    bench = load_script("benchmarks/bench_policy_box.py")
    out = tmp_path / "box.json"
    assert bench.main(["--rounds", "3", "--periods", "5", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert set(result["median_ms"]) == {"models/cchp_path_shape.pt", "models/cchp_default.pt"}
    for name, rounds in result["ms_per_period"].items():
        assert len(rounds) == 3 and all(r > 0 for r in rounds)
        assert result["median_ms"][name] == statistics.median(rounds[1:])


def test_bench_run_cost_runs_a_checkout_with_its_own_models(tmp_path, load_script):
    """Another checkout's run loads its own `rtcohand_drake` and its own `models/`: the models package
    (`rtcohand_drake_models`), which the editable install maps to the installed checkout, is linked for
    it; `PYTHONPATH` alone would give it the installed checkout's model files."""
    import os
    import shutil

    bench = load_script("benchmarks/bench_run_cost.py")
    other = tmp_path / "other"
    shutil.copytree(REPO / "rtcohand_drake", other / "rtcohand_drake", ignore=shutil.ignore_patterns("__pycache__"))
    (other / "models").mkdir()
    for name in ("__init__.py", "package.xml"):
        shutil.copy(REPO / "models" / name, other / "models" / name)
    probe = "from rtcohand_drake.cell.robot_files import models_dir; print(models_dir())"

    def models_of(env):
        done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, cwd=other,
                              check=True)
        return Path(done.stdout.strip()).resolve()

    assert models_of(bench._env(other)) == (other / "models").resolve()
    bench.check_checkout(other)
    plain = dict(os.environ, PYTHONPATH=str(other))
    assert models_of(plain) != (other / "models").resolve()  # the installed models: what it measured before
