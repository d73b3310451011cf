"""Paths as results files write them: relative to the repository, never the checkout's own place.

Results files (`docs/results/`: a study's `study.json`, the benchmarks' JSON,
logs kept beside them) are committed and read on other machines, where the
checkout they ran in (`/home/me/rtcohand_drake/...`) means nothing. A path
inside the repository is written relative to its root
(`models/cchp_default.pt`, `out/study/logs/p121_u10_gestures_s0.h5`); one
inside the working folder, relative to that; any other (a cluster's shared
folder, say) as it was given.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def repo_relative(path: str | os.PathLike) -> str:
    """`path` as a results file writes it (module docstring), with `/` separators."""
    absolute = Path(path).resolve()
    for root in (REPO, Path.cwd().resolve()):
        try:
            return absolute.relative_to(root).as_posix() or "."
        except ValueError:
            continue
    return str(path)


def checkout_commit(folder: str | os.PathLike = REPO) -> str:
    """What a results file says a checkout was: its commit (short hash), "with changes" when its
    working tree differs from it; "(not a git checkout)" otherwise."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(folder), *args], capture_output=True, text=True,
                              check=True).stdout.strip()

    try:
        commit = git("rev-parse", "--short", "HEAD")
        changed = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.CalledProcessError):
        return "(not a git checkout)"
    return f"{commit} with changes" if changed else commit
