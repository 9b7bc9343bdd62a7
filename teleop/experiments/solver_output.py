"""Keep the solvers off the console during ``compare``, ``replay`` and ``bench``
(docs/design.md section 15.5).

OSQP 1.x prints "Polishing not needed - no active set detected at optimal point" from its C
code whenever a polished solve has no active constraint, whatever ``verbose`` says; other
backends warn through :mod:`warnings` (qpsolvers' sparse conversions). While a
:class:`SolverOutputCapture` is open, file descriptors 1 and 2, ``sys.stdout`` and
``sys.stderr`` all write to one temporary file, and warnings are recorded instead of shown;
:meth:`SolverOutputCapture.collect` returns what was written since the last call, each
distinct line with its count, for the report and metrics.json.

The capture is process-wide (file descriptors are), so it is for the command-line runs
only, never for a server with other threads writing.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import ctypes.util
import functools
import io
import os
import sys
import tempfile
import warnings
from typing import TextIO


@functools.cache
def _libc() -> ctypes.CDLL | None:
    """The C library, for ``fflush`` (None where there is none to load)."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or None)
    except OSError:
        return None


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers, so nothing printed inside leaks out later."""
    libc = _libc()
    if libc is not None:
        libc.fflush(None)


class SolverOutputCapture(contextlib.AbstractContextManager):
    """Redirect everything written to the console into a temporary file while open.

    Attributes
    ----------
    console : a text stream to the terminal's standard error as it was on entry, for a
        progress bar (valid while the capture is open).
    """

    def __init__(self) -> None:
        self.console: TextIO | None = None
        self._file: io.FileIO | None = None
        self._offset = 0
        self._saved: dict[int, int] = {}
        self._streams = contextlib.ExitStack()
        self._warnings: list[warnings.WarningMessage] = []
        self._warnings_seen = 0

    def __enter__(self) -> "SolverOutputCapture":
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        _flush_c_stdio()
        descriptor, path = tempfile.mkstemp(prefix="teleop-solver-output-")
        os.close(descriptor)
        self._file = open(path, "a+b", buffering=0)  # appends: every writer lands at the end
        os.unlink(path)
        try:
            self._redirect()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _redirect(self) -> None:
        """Point fds 1 and 2, ``sys.stdout``, ``sys.stderr`` and warnings at the capture."""
        for fd in (1, 2):
            self._saved[fd] = os.dup(fd)
            os.dup2(self._file.fileno(), fd)
        self.console = os.fdopen(os.dup(self._saved[2]), "w", buffering=1)
        text = io.TextIOWrapper(open(os.dup(self._file.fileno()), "ab", buffering=0),
                                encoding="utf-8", errors="replace", line_buffering=True)
        self._streams.enter_context(text)
        self._streams.enter_context(contextlib.redirect_stdout(text))
        self._streams.enter_context(contextlib.redirect_stderr(text))
        self._warnings = self._streams.enter_context(warnings.catch_warnings(record=True))

    def collect(self) -> dict[str, int]:
        """Every distinct line written (and warning raised) since the last call, with its
        count: ``{"Polishing not needed - ...": 912, "UserWarning: ...": 1}``."""
        sys.stdout.flush()
        sys.stderr.flush()
        _flush_c_stdio()
        size = os.fstat(self._file.fileno()).st_size
        data = os.pread(self._file.fileno(), size - self._offset, self._offset)
        self._offset = size
        lines = collections.Counter(
            line.strip() for line in data.decode("utf-8", errors="replace").splitlines()
            if line.strip())
        for message in self._warnings[self._warnings_seen:]:
            lines[f"{message.category.__name__}: {message.message}"] += 1
        self._warnings_seen = len(self._warnings)
        return dict(lines)

    def __exit__(self, *exc_info) -> None:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            _flush_c_stdio()
        finally:
            self._streams.close()
            for fd, saved in self._saved.items():
                os.dup2(saved, fd)
                os.close(saved)
            self._saved.clear()
            if self.console is not None:
                self.console.close()
                self.console = None
            self._file.close()
