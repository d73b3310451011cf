"""tests/test_safety_properties.py fails, not skips, when the policy it is told to check is missing."""

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_a_missing_property_model_fails_the_property_test(tmp_path):
    missing = tmp_path / "none.pt"
    env = dict(os.environ, RTCOHAND_PROPERTY_MODEL=str(missing), RTCOHAND_PROPERTY_EXAMPLES="1")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "tests/test_safety_properties.py"], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 1, proc.stdout[-2000:]
    assert "no such policy file" in proc.stdout and "skipped" not in proc.stdout
