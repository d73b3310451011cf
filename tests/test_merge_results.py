"""benchmarks/merge_results.py: which evaluate results may share one table."""

import importlib.util
import pathlib

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "merge_results.py"


def _merge():
    spec = importlib.util.spec_from_file_location("merge_results", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.merged_table


def _result(data, zero=0.02, ridge=0.005, name="m", mse=0.01):
    return {"data": data, "seed": 0, "episodes": {"Own": 120},
            "reference": {"zero_twist_mse": {"Own": zero}, "ridge_mse": {"Own": ridge}},
            "models": {name: {"seeds": 3, "settings": {"Own": {"mse": mse, "mse_std": 0.001}}}}}


def test_the_same_episodes_at_another_path_merge():
    table = _merge()([_result("out/a.h5", name="A"), _result("out/b.h5", name="B", mse=0.03)])
    assert "| A | 3 | 0.0100 ± 0.0010 (0.50x) |" in table and "| B | 3 | 0.0300 ± 0.0010 (1.50x) |" in table


def test_other_episodes_at_another_path_are_refused():
    with pytest.raises(SystemExit, match="differ in 'data'"):
        _merge()([_result("out/a.h5"), _result("out/b.h5", zero=0.021)])
