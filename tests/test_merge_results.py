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


def test_no_files_a_missing_file_or_another_json_is_one_line(tmp_path):
    import subprocess
    import sys

    other = tmp_path / "other.json"
    other.write_text('{"a": 1}')
    for args in ([], [str(tmp_path / "none.json")], [str(other)]):
        run = subprocess.run([sys.executable, SCRIPT] + args, capture_output=True, text=True)
        assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr


def test_results_written_before_the_ridge_reference_merge_without_its_row(load_script):
    old = [_result("out/a.h5", name="A"), _result("out/a.h5", name="B")]
    for r in old:
        del r["reference"]["ridge_mse"]
    table = load_script(SCRIPT).merged_table(old)
    assert "| A | 3 |" in table and "| B | 3 |" in table and "ridge" not in table
