"""MediaPipe's and LiteRT's own INFO and WARNING lines, kept off stderr while a landmarker is open.

The C++ side of MediaPipe (and LiteRT, TensorFlow Lite and absl under it)
writes about a dozen lines to the process's file descriptor 2 when a hand
landmarker starts, on its first frames and when it closes, and none of them
can be turned off from Python (no environment variable reaches them). Some
come late, from MediaPipe's own threads: the warning about the alignment of
an input tensor's memory, say, on whichever frame first has such a tensor.

So while the filter is held (`hold()` ... `release()`: by each
`HandLandmarker` while it is open, unless `verbose=True`, the commands'
`--verbose`), descriptor 2 is a pipe, and a thread passes on everything
written to it except the libraries' INFO and WARNING lines
(`LIBRARY_LINE`). Errors (`E...`, `F...` lines) and every line of the
program's own (lower-case `warning:` lines, Python's `WARNING:name:` log
lines, tracebacks, progress bars) pass through unchanged, in order. When the
last holder lets go, descriptor 2 is the terminal (or file) again.
"""

from __future__ import annotations

import os
import re
import sys
import threading

# LiteRT and TensorFlow Lite: "INFO: [environment.cc:36] ...", "WARNING: Read-only tensor ...";
# absl/glog: "W0000 00:00:1796554543.892350    3745 inference_runner_litert.cc:1433] ...".
LIBRARY_LINE = re.compile(rb"(?:INFO|WARNING): |[IW]\d{4} [\d:.]+ +\d+ [\w.\-]+:\d+\] ")


def library_line(line: bytes) -> bool:
    """Whether a line on stderr is one of the libraries' INFO or WARNING lines."""
    return LIBRARY_LINE.match(line) is not None


class _Filter:
    """Descriptor 2 through a pipe; a thread passes on all but the libraries' lines."""

    def __init__(self):
        sys.stderr.flush()
        self._terminal = os.dup(2)
        read, write = os.pipe()
        os.dup2(write, 2)
        os.close(write)
        self._read = read
        self._thread = threading.Thread(target=self._pump, name="library-log-filter", daemon=True)
        self._thread.start()

    def _write(self, data: bytes) -> None:
        try:
            while data:
                data = data[os.write(self._terminal, data):]
        except OSError:  # stderr closed (a reader gone): the pipe is still drained, so no writer blocks
            pass

    def _pump(self) -> None:
        pending = b""  # the start of a line that may yet turn out to be a library's
        passing = False  # within a line already passed on (a progress bar's, say)
        while True:
            chunk = os.read(self._read, 65536)
            if not chunk:
                break
            data, pending, out = pending + chunk, b"", []
            while data:
                end = data.find(b"\n") + 1
                if passing:
                    out.append(data[:end] if end else data)
                    data, passing = (data[end:], False) if end else (b"", True)
                elif end:
                    if not library_line(data[:end]):
                        out.append(data[:end])
                    data = data[end:]
                elif data[:1] in (b"I", b"W"):  # could be a library's line: wait for its end
                    pending, data = data, b""
                else:
                    out.append(data)
                    data, passing = b"", True
            if out:
                self._write(b"".join(out))
        if pending and not library_line(pending):
            self._write(pending)
        os.close(self._read)

    def stop(self) -> None:
        sys.stderr.flush()
        os.dup2(self._terminal, 2)  # the pipe's last writer is gone: the thread drains it and ends
        self._thread.join(timeout=5.0)
        os.close(self._terminal)


_lock = threading.Lock()
_holders = 0
_filter: _Filter | None = None


def hold() -> None:
    """Starts hiding the libraries' lines (or counts one more holder)."""
    global _holders, _filter
    with _lock:
        if _holders == 0:
            _filter = _Filter()
        _holders += 1


def release() -> None:
    """One holder fewer; with none left, stderr is passed straight through again."""
    global _holders, _filter
    with _lock:
        _holders -= 1
        if _holders == 0 and _filter is not None:
            _filter.stop()
            _filter = None
