"""Real-time scheduling of the threads on the wire (docs/ros2.md, "Real-time threads"), as
ros2_control's ``controller_manager`` asks for its update thread (``SCHED_FIFO``,
``thread_priority`` 50).

Over DDS the loop and the robot run on two clocks: the robot applies at each update the
newest command it has, so a command that misses its update (the loop's process not
scheduled in time) is replaced by the last one held, and the next two arrive in one
period (one never acts). On a loaded machine the ordinary scheduler lets a process wait
for milliseconds, the length of a period at 500 Hz; a ``SCHED_FIFO`` thread runs as soon
as it is woken, ahead of every ordinary one. :func:`make_realtime` puts the calling thread
there; :func:`started_realtime` does it while a function starts threads (DDS's receive
and delivery threads, a watchdog), which inherit it, and gives the calling thread its own
scheduling back afterwards (a participant joining a domain whose threads another one of
the process started earlier starts none: they stay as they were, and the words say so).
Without the privilege (``CAP_SYS_NICE`` or an ``RLIMIT_RTPRIO`` of at least the priority)
the threads stay as they were and the words say so: they are what the plant's measures
and the simulated robot report."""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from typing import Callable, TypeVar

T = TypeVar("T")

#: periods in a row with no time left to sleep (the loop's tick, or the simulated robot's
#: physics, overran them) after which a real-time thread goes back to ordinary scheduling:
#: one that never sleeps would hold its core against every ordinary thread
OVERRUN_PERIODS = 10

#: SCHED_FIFO's highest priority on Linux (the lowest is 1)
MAX_PRIORITY = 99
#: ros2_control's ``controller_manager`` update thread's priority (its ``thread_priority``):
#: the simulated robot (``teleop sim --ros2``) plays the robot and runs at it
ROBOT_PRIORITY = 50
#: the loop side's priority, strictly below the robot's: on the robot's own machine a
#: loop thread that overran its period (it never sleeps) must not take a core from the
#: robot's update thread (docs/ros2.md "Real-time threads")
LOOP_PRIORITY = 40


def check_priority(priority: object) -> int:
    """``priority`` as a whole number in [0, 99] (0: ordinary scheduling), else
    ``ValueError`` naming it."""
    if (isinstance(priority, bool) or not isinstance(priority, int)
            or not 0 <= priority <= MAX_PRIORITY):
        raise ValueError(f"realtime_priority must be a whole number in [0, {MAX_PRIORITY}] "
                         f"(0: not real-time), got {priority!r}")
    return priority


def scheduling_words() -> str:
    """How the calling thread is scheduled, in words (``SCHED_FIFO 40``)."""
    policy = os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK
    name = {os.SCHED_FIFO: "SCHED_FIFO", os.SCHED_RR: "SCHED_RR"}.get(policy)
    if name is None:
        return "ordinary scheduling"
    return f"{name} {os.sched_getparam(0).sched_priority}"


def make_realtime(priority: int, reset_on_fork: bool = True) -> str:
    """The calling thread scheduled ``SCHED_FIFO`` at ``priority`` (1-99; 0: left as it
    is), with ``SCHED_RESET_ON_FORK`` unless ``reset_on_fork`` is false: the threads and
    processes it starts then run ordinary (none inherits ``SCHED_FIFO`` unawares).
    Returns how it is scheduled then, with the reason when the system refused
    (``ValueError`` for a priority outside [0, 99])."""
    if check_priority(priority) == 0:
        return scheduling_words()
    policy = os.SCHED_FIFO | (os.SCHED_RESET_ON_FORK if reset_on_fork else 0)
    try:
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except OSError as error:
        return (f"{scheduling_words()} (SCHED_FIFO {priority} refused: "
                f"{error.strerror or error})")
    return scheduling_words()


@dataclass(frozen=True)
class ThreadScheduling:
    """A thread's scheduling as it was, to give it back (:meth:`restore`, from any
    thread while it is alive)."""

    thread: threading.Thread
    thread_id: int
    policy: int
    priority: int

    @classmethod
    def of_calling_thread(cls) -> "ThreadScheduling":
        """The calling thread's scheduling now."""
        return cls(threading.current_thread(), threading.get_native_id(),
                   os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)

    def restore(self) -> bool:
        """The thread scheduled as it was, when it is still alive (whether it was): the
        kernel's thread id of an ended thread may be another's by now, which is left
        alone. The calling thread restores itself by no id."""
        if self.thread is threading.current_thread():
            thread_id = 0
        elif self.thread.is_alive():
            thread_id = self.thread_id
        else:
            return False
        try:
            os.sched_setscheduler(thread_id, self.policy, os.sched_param(self.priority))
        except ProcessLookupError:
            return False
        return True


#: the threads :func:`hold_realtime` made real-time: their scheduling before the first
#: hold and how many holds are on them (two plants may actuate from one thread)
_holds: dict[int, tuple[ThreadScheduling, int]] = {}
_holds_lock = threading.Lock()


def hold_realtime(priority: int) -> tuple[int, str]:
    """The calling thread made real-time (:func:`make_realtime`) for one more holder;
    returns its id (for :func:`release_realtime`) and the words."""
    thread_id = threading.get_native_id()
    with _holds_lock:
        before, holders = _holds.get(thread_id, (ThreadScheduling.of_calling_thread(), 0))
        if before.thread is not threading.current_thread():  # an ended thread's id
            before, holders = ThreadScheduling.of_calling_thread(), 0
        words = make_realtime(priority)
        _holds[thread_id] = (before, holders + 1)
    return thread_id, words


def release_realtime(thread_id: int) -> None:
    """One hold of :func:`hold_realtime` on ``thread_id`` released: with the last, the
    thread is scheduled as before the first (another holder's hold stays in force)."""
    with _holds_lock:
        before, holders = _holds.pop(thread_id)
        if holders > 1:
            _holds[thread_id] = (before, holders - 1)
        else:
            before.restore()


def started_realtime(priority: int, start: Callable[[], T]) -> tuple[T, str]:
    """``start()`` called with the calling thread ``SCHED_FIFO`` at ``priority`` (without
    ``SCHED_RESET_ON_FORK``, which would stop just that), so the threads it starts
    inherit it; after it, the calling thread is scheduled as before.
    Returns what ``start`` returned and the words: the scheduling and how many threads
    started (``SCHED_FIFO 50, 5 threads started``)."""
    caller = ThreadScheduling.of_calling_thread()
    before = set(os.listdir("/proc/self/task"))
    words = make_realtime(priority, reset_on_fork=False)
    try:
        result = start()
    finally:
        caller.restore()
    started = len(set(os.listdir("/proc/self/task")) - before)
    return result, (f"{words}, {started} thread{'s' * (started != 1)} started" if started
                    else "no thread started (those already running unchanged)")
