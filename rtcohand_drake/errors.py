"""Errors for bad input, and the one-line, exit-status-2 convention of every CLI.

Bad input (a missing or corrupt file, a malformed scenario, a wrong argument)
raises `InputError` (or a subclass) whose message is one line naming the file
and the problem. `run_cli` turns it into that line on stderr and exit status 2.
Internal bugs are not InputErrors and keep their traceback.
"""

from __future__ import annotations

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
