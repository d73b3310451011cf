"""benchmarks/merge_results.py: which evaluate results may share one table."""

import pytest

SCRIPT = "benchmarks/merge_results.py"


def _result(data, zero=0.02, ridge=0.005, name="m", mse=0.01):
    return {"data": data, "seed": 0, "episodes": {"Own": 120},
            "reference": {"zero_twist_mse": {"Own": zero}, "ridge_mse": {"Own": ridge}},
            "models": {name: {"seeds": 3, "settings": {"Own": {"mse": mse, "mse_std": 0.001}}}}}


def test_the_same_episodes_at_another_path_merge(load_script):
    table = load_script(SCRIPT).merged_table([_result("out/a.h5", name="A"), _result("out/b.h5", name="B", mse=0.03)])
    assert "| A | 3 | 0.0100 ± 0.0010 (0.50x) |" in table and "| B | 3 | 0.0300 ± 0.0010 (1.50x) |" in table


def test_other_episodes_at_another_path_are_refused(load_script):
    with pytest.raises(SystemExit, match="differ in 'data'"):
        load_script(SCRIPT).merged_table([_result("out/a.h5"), _result("out/b.h5", zero=0.021)])
