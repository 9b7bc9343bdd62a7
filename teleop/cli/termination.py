"""A command that drives a robot stops the same way whatever stops it.

Python turns Ctrl-C (SIGINT) into ``KeyboardInterrupt``, which unwinds through the
commands' ``finally`` blocks and ``atexit``: a ROS 2 robot gets its zeros
(:meth:`teleop.plants.ros2.ros2_plant.Ros2Plant.close`), a recording its last lines. A
service manager, ``kill`` or a closed terminal sends SIGTERM or SIGHUP instead, whose
default ends the process at once: none of that runs, and a ros2_control velocity
controller holds the last command. :func:`terminations_interrupt` makes both unwind as
Ctrl-C does.

A SIGINT the command was started with ignored (a background job of a shell without job
control, ``nohup``) stays ignored, as Python leaves it: such a job is meant to outlive the
terminal's Ctrl-C, and SIGTERM is how it is stopped.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

#: the signals that end a command as Ctrl-C does
TERMINATIONS = (signal.SIGTERM, signal.SIGHUP)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


@contextmanager
def terminations_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise ``KeyboardInterrupt`` in the main
    thread; the previous handlers come back after it. Outside the main thread (a command
    run from a test's or an application's thread) nothing changes: Python lets only the
    main thread set handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, _interrupt) for signum in TERMINATIONS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
