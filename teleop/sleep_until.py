"""Sleep to an absolute deadline on the monotonic clock, as a real-time loop keeps its
period (ros2_control's ``controller_manager`` sleeps until its next update's time point;
docs/ros2.md "Real-time threads").

A loop that sleeps "one period" after its work drifts by the work's length and by every
wake-up's lateness; one that sleeps to ``start + k dt`` does not. On Linux the sleep is
``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`` (the clock of ``time.monotonic``), so
nothing between reading the clock and sleeping shifts the wake-up, and a signal handled
during the sleep does not end it early: it sleeps on to the same deadline. Elsewhere it
falls back to ``time.sleep`` of what is left.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import math
import sys
import time
from typing import Callable

#: Linux's CLOCK_MONOTONIC (time.monotonic's clock) and TIMER_ABSTIME
CLOCK_MONOTONIC = 1
TIMER_ABSTIME = 1
#: the seconds a C ``long`` (``struct timespec``'s ``tv_sec``) holds: a deadline at or
#: beyond it would wrap (2**63 s to a past one, 1.9e19 s to 5.5e17 s away)
LATEST = float(2 ** (8 * ctypes.sizeof(ctypes.c_long) - 1))


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _clock_nanosleep() -> Callable[..., int] | None:
    """libc's ``clock_nanosleep`` (the GIL released while it sleeps), None off Linux."""
    if not sys.platform.startswith("linux"):
        return None
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=False)
    function = getattr(libc, "clock_nanosleep", None)
    if function is None:
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec),
                         ctypes.POINTER(_Timespec)]
    function.restype = ctypes.c_int  # the error number itself (0: slept to the end)
    return function


_CLOCK_NANOSLEEP = _clock_nanosleep()


def sleep_until(deadline: float) -> None:
    """The calling thread asleep until ``time.monotonic()`` reaches ``deadline`` (s);
    returns at once when it already has. ``ValueError`` for a deadline that is not a
    finite number of seconds below :data:`LATEST` (a ``struct timespec``'s ``tv_sec``
    would wrap)."""
    if isinstance(deadline, bool) or not isinstance(deadline, (int, float)) \
            or not math.isfinite(deadline) or abs(deadline) >= LATEST:
        raise ValueError(f"deadline must be a finite number of seconds under {LATEST:.3g}, "
                         f"got {deadline!r}")
    if _CLOCK_NANOSLEEP is None:
        time.sleep(max(0.0, deadline - time.monotonic()))
        return
    seconds = math.floor(deadline)
    point = _Timespec(seconds, min(999_999_999, round((deadline - seconds) * 1e9)))
    while _CLOCK_NANOSLEEP(CLOCK_MONOTONIC, TIMER_ABSTIME, ctypes.byref(point), None) \
            == errno.EINTR:
        pass  # a signal: its Python handler runs between the calls, then on to the deadline
