"""Headless Chromium for looking at Meshcat: screenshots and page checks.

Chromium is a system package (`apt-get install -y chromium`), not a Python
dependency; `find_chromium()` says clearly when it is missing. Flags keep a
headless Chromium from reaching out to the network on start.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

from rtcohand_drake.errors import InputError

HEADLESS_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic")


def find_chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if path is None:
        raise InputError("chromium: not found; install it with `apt-get install -y chromium`")
    return path


def screenshot(url: str, out: str | Path, width: int = 1280, height: int = 800,
               budget_ms: int = 8000, timeout_s: float = 120.0) -> Path:
    """Loads `url` in headless Chromium and saves a PNG screenshot to `out`."""
    out = Path(out).resolve()
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([find_chromium(), *HEADLESS_FLAGS, f"--user-data-dir={profile}",
                        f"--screenshot={out}", f"--window-size={width},{height}",
                        f"--virtual-time-budget={budget_ms}", url],
                       check=True, capture_output=True, timeout=timeout_s)
    return out
