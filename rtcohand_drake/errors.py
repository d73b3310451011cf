"""Errors for bad input, and the one-line, exit-status-2 convention of every CLI.

Bad input (a missing or corrupt file, a malformed scenario, a wrong argument)
raises `InputError` (or a subclass) whose message is one line naming the file
and the problem. `run_cli` turns it into that line on stderr and exit status 2.
Internal bugs are not InputErrors and keep their traceback.
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence


class InputError(ValueError):
    """Bad input from a user: a file, a flag or a value. The message is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


def one_line(message: str) -> str:
    """Collapses a (possibly multi-line) message into one line."""
    return " ".join(str(message).split())


def input_error_types() -> tuple[type[BaseException], ...]:
    """All exception types that mean "bad input" across the package.

    Modules with their own error class (datasets, checkpoints, models) derive
    it from `InputError`; this indirection keeps the list in one place.
    """
    return (InputError,)


def run_cli(main: Callable[[Sequence[str] | None], int | None],
            argv: Sequence[str] | None = None, prog: str = "rtcohand_drake") -> int:
    """Runs a CLI entry point; bad input becomes one stderr line and status 2."""
    try:
        status = main(argv)
    except input_error_types() as err:
        print(f"{prog}: error: {one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    return int(status or 0)


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose own errors (an unknown flag, a bad value) raise an `InputError`: one line
    on stderr and status 2 under `run_cli`, instead of the usage text."""

    def error(self, message):
        raise InputError(f"command line: {message}")


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0 (a seed, a camera number, a count that may be zero)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0 (a rate, a time)."""
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def writable_file_path(path, flag: str) -> None:
    """Raises an InputError unless `path` may be written as a file: not a folder, in a folder that exists
    and may be written to. Called before the work whose result it will hold."""
    from pathlib import Path

    path = Path(path)
    if path.is_dir():
        raise InputError(f"{flag} {path}: is a folder; give a file path")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{flag} {path}: folder {parent} does not exist")
    try:  # a file made and removed there: the folder's permissions alone do not say (a read-only mount)
        import tempfile

        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as err:
        raise InputError(f"{flag} {path}: folder {parent} cannot be written to ({err.strerror})") from None
