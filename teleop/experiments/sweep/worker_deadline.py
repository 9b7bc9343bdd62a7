"""A Ray task's worker ends itself past its cell's deadline (docs/sweep.md, "Engines").

A cell stuck in native code cannot check its clock, and the driver cannot stop it safely:
``ray.cancel(force=True)`` racing the task's own end trips Ray's check "Tried to complete
task that was not pending" (ray-project/ray#54798) and ends the driver with exit 1. So the
task arms the kernel's real-time timer as it starts: SIGALRM at its default action ends
the worker's process without running any Python code (a stuck call holding the
interpreter cannot delay it), the driver sees the worker die and fails the cell, and no
task is ever cancelled at its time limit.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def ended_past(seconds: float) -> Iterator[bool]:
    """Within the block, the kernel ends this process ``seconds`` from now (SIGALRM at
    its default action); on leaving, the timer and SIGALRM's handler are as before.
    Yields whether the timer is armed: not outside the main thread (where Python cannot
    set a handler) nor where ``setitimer`` is missing (not Unix)."""
    if not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread():
        yield False
        return
    previous = signal.signal(signal.SIGALRM, signal.SIG_DFL)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield True
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        if previous is not None:  # None: a handler set outside Python, not restorable
            signal.signal(signal.SIGALRM, previous)
