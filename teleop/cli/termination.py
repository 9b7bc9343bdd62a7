"""A command that drives a robot stops the same way whatever stops it.

Python turns Ctrl-C (SIGINT) into ``KeyboardInterrupt``, which unwinds through the
commands' ``finally`` blocks and ``atexit``: a ROS 2 robot gets its zeros
(:meth:`teleop.plants.ros2.ros2_plant.Ros2Plant.close`), a recording its last lines. A
service manager, ``kill`` or a closed terminal sends SIGTERM or SIGHUP instead, whose
default ends the process at once: none of that runs, and a ros2_control velocity
controller holds the last command. :func:`terminations_interrupt` makes them unwind as
Ctrl-C does, once: a second signal while the cleanup runs (Ctrl-C pressed twice, a
hang-up then a TERM) is ignored, so it never cuts the zeros short.

A signal the command was started with ignored stays ignored, as Python leaves an ignored
SIGINT: a background job of a shell without job control ignores SIGINT and one under
``nohup`` SIGHUP, both meant to outlive the terminal; SIGTERM stops them.

A command whose cleanup is complete when it is stopped (``teleop sweep``: its database
closed, its workers and its Ray instance stopped) says so by raising
:class:`CleanedUpInterrupt`; the program's entry (:func:`teleop.cli.main` called as the
``teleop`` program) then ends the process at once (:func:`end_process`) instead of
waiting for the interpreter's teardown (Ray's extension takes 1-3 s there,
docs/sweep.md). A caller that runs a command in its own process (a test, a script) gets
the exit code back as before.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

#: the signals that end a command as Ctrl-C does
TERMINATIONS = (signal.SIGTERM, signal.SIGHUP)


@contextmanager
def terminations_interrupt() -> Iterator[None]:
    """Within the block, the first of SIGINT, SIGTERM and SIGHUP raises
    ``KeyboardInterrupt`` (its argument the signal's name) in the main thread and the
    later ones are ignored; a signal ignored on entry stays ignored. The previous
    handlers come back after the block. Outside the main thread (a command run from a
    test's or an application's thread) nothing changes: Python lets only the main thread
    set handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    interrupted = False

    def interrupt(signum: int, frame: FrameType | None) -> None:
        nonlocal interrupted
        if interrupted:  # the cleanup of the first is running: let it finish
            return
        interrupted = True
        raise KeyboardInterrupt(signal.Signals(signum).name)

    previous = {signum: signal.signal(signum, interrupt)
                for signum in (signal.SIGINT, *TERMINATIONS)
                if signal.getsignal(signum) is not signal.SIG_IGN}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


class CleanedUpInterrupt(KeyboardInterrupt):
    """A command stopped by a signal (its argument the signal's name) after its own
    cleanup ran to the end: nothing is left to close, the process may end at once."""


def end_process(code: int) -> None:
    """End the process with ``code`` now: the standard streams flushed, the interpreter's
    teardown (``atexit``, the modules' finalizers) skipped. Only for a process whose
    work is all closed (:class:`CleanedUpInterrupt`)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed, or a broken pipe: nothing more to write
            pass
    os._exit(code)
