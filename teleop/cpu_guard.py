"""A real-time thread's CPU guard (docs/design.md section 5.3, "Priorities"; docs/ros2.md
"Real-time threads").

A ``SCHED_FIFO`` thread runs ahead of every ordinary one: one that never sleeps holds its
core against all of them (and against any real-time thread not above it). So the thread
measures its own CPU time over windows of :data:`WINDOW` s: above :data:`SHARE` of one
CPU it goes back to ordinary scheduling, and takes real-time again once its windows ran
:data:`QUIET_RETAKE` s in a row at or under that share. Time spent waiting (for a lock,
the interpreter, a sleep) is no CPU time: a thread late because it waits is not given up.
The page's control thread (``web.app.ControlThread``) and the simulated ROS 2 robot's
periods (``teleop sim --ros2``) run under one each.
"""

from __future__ import annotations

import enum
import time

#: the real-time thread's CPU time is checked over windows of this length (s)...
WINDOW = 0.25
#: ... and above this share of one CPU it goes back to ordinary scheduling ...
SHARE = 0.9
#: ... and retakes real-time after this long (s) of windows under that share
QUIET_RETAKE = 2.0


class Verdict(enum.Enum):
    """What :meth:`CpuGuard.check` asks of the thread."""

    MID_WINDOW = "the window runs on"
    KEEP = "a window ended: keep the scheduling as it is"
    GIVE_UP = "a window ended over the share: give real-time up"
    RETAKE = "a window ended the quiet time: take real-time again"


class CpuGuard:
    """The guard of the thread that calls :meth:`check` (module docstring). Built and
    checked in the guarded thread: its CPU clock is the calling thread's."""

    def __init__(self) -> None:
        #: real-time given up for the share, until :meth:`check` says RETAKE (or
        #: :meth:`taken_again`)
        self.given_up = False
        #: the thread's CPU time over the last window ended, per second of it
        self.share = 0.0
        self._quiet = 0.0  # how long the windows ran under the share since it was given up
        self._start = time.perf_counter()
        self._cpu = time.thread_time()

    def restart(self) -> None:
        """A new window from now (a new rate: the last window's ticks say nothing of it)."""
        self._start, self._cpu = time.perf_counter(), time.thread_time()

    def taken_again(self) -> None:
        """The thread took real-time again on its own (a new rate): no longer given up."""
        self.given_up, self._quiet = False, 0.0

    def check(self, holding: bool) -> Verdict:
        """Called by the guarded thread once a period; ``holding``: it is real-time by its
        own hold now. At a window's end, :attr:`share` measured: GIVE_UP when holding and
        over :data:`SHARE`; RETAKE when given up and its windows ran :data:`QUIET_RETAKE`
        s under it; KEEP otherwise. MID_WINDOW before."""
        now = time.perf_counter()
        if now - self._start < WINDOW:
            return Verdict.MID_WINDOW
        cpu = time.thread_time()
        self.share = (cpu - self._cpu) / (now - self._start)
        verdict = Verdict.KEEP
        if holding and self.share > SHARE:
            self.given_up, self._quiet, verdict = True, 0.0, Verdict.GIVE_UP
        elif self.given_up:
            self._quiet = self._quiet + (now - self._start) if self.share <= SHARE else 0.0
            if self._quiet >= QUIET_RETAKE:
                self.taken_again()
                verdict = Verdict.RETAKE
        self._start, self._cpu = now, cpu
        return verdict
