"""The server's other threads scheduled real-time, below the control thread (docs/design.md
section 5.3, "Priorities").

The control thread runs ``SCHED_FIFO`` (:class:`web.app.ControlThread`), so no other
process keeps it from a CPU. But it shares the interpreter (the GIL) and the app's lock
with the server's other threads: the view, the inbox, the inputs' receivers, viser's
event loop and its callbacks. An ordinary thread that the system preempts while it holds
either waits for a CPU behind every other process of a loaded machine, and the control
thread waits with it (a priority inversion): under a datagram flood on this 2-core
machine those threads waited 0.8-0.9 s per second for a CPU and the loop fell to 0.5 of
its rate (docs/inputs.md, "Floods"). So they run ``SCHED_FIFO`` at
:data:`SHARED_PRIORITY`, the lowest: ahead of every ordinary thread, behind the control
thread and any other real-time thread. Each does bounded work (the receivers read in
bounded batches, the page's messages are paced, the view draws at 30 Hz, the inbox
coalesces and throttles), and all of them together hold at most the one interpreter.
They are set ``SCHED_RESET_ON_FORK``: a process or thread they start (a compiler, a
lookup) runs ordinary.

They are real-time only while the control thread is (:class:`SharedPriority`, followed by
the control thread itself): when it gives ``SCHED_FIFO`` up, runs at priority 0, or was
refused, FIFO 1 threads would run ahead of it, so they go back to ordinary scheduling with
it and are raised again when it retakes. Only the server's own threads are taken (the
view, the inbox, the inputs' receivers, viser's event loop, the callback pool), and never
one already real-time (a plant's watchdog at its own priority stays there).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor

#: ``SCHED_FIFO``'s lowest priority: the server's threads other than the control thread
SHARED_PRIORITY = 1

#: the real-time policies (what a thread that is "already real-time" runs)
REALTIME_POLICIES = (os.SCHED_FIFO, os.SCHED_RR)


def is_realtime(thread_id: int = 0) -> bool:
    """Whether kernel thread ``thread_id`` (0: the calling thread) runs a real-time policy
    (False when it has ended)."""
    try:
        policy = os.sched_getscheduler(thread_id) & ~os.SCHED_RESET_ON_FORK
    except OSError:
        return False
    return policy in REALTIME_POLICIES


def make_shared_realtime(thread_id: int = 0) -> str:
    """The thread ``thread_id`` (a kernel thread id; 0: the calling thread) scheduled
    ``SCHED_FIFO`` at :data:`SHARED_PRIORITY` with ``SCHED_RESET_ON_FORK``; "" when it
    is, else why not (the system refused: no privilege; the thread ended)."""
    try:
        os.sched_setscheduler(thread_id, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK,
                              os.sched_param(SHARED_PRIORITY))
    except OSError as error:
        return error.strerror or str(error)
    return ""


def make_ordinary(thread_id: int = 0) -> None:
    """The thread ``thread_id`` (0: the calling thread) back to ordinary scheduling (an
    ended one is left alone)."""
    try:
        os.sched_setscheduler(thread_id, os.SCHED_OTHER, os.sched_param(0))
    except OSError:
        pass


class SharedPriority:
    """The server's own ``threads`` and the workers of its ``pools``, real-time at
    :data:`SHARED_PRIORITY` exactly while the control thread is (:meth:`follow`).

    A thread already real-time when it is raised (another part's, at its own priority)
    is never touched; only those raised here are lowered. :attr:`words` says how they run.
    """

    def __init__(self, threads: Iterable[threading.Thread],
                 pools: Iterable[ThreadPoolExecutor] = ()) -> None:
        self._threads = list(threads)
        self._pools = list(pools)
        #: the threads this made real-time (lowered again by :meth:`follow`)
        self._raised: set[threading.Thread] = set()
        self._lock = threading.Lock()
        #: whether the threads are to run real-time now (the control thread's state)
        self.realtime = False
        #: how the threads run, in words ("": as they were, nothing followed yet)
        self.words = ""
        for pool in self._pools:  # its workers start as callbacks come: each sets itself
            pool._initializer = self._worker_started

    def _members(self) -> list[threading.Thread]:
        workers = [worker for pool in self._pools for worker in list(pool._threads)]
        return [thread for thread in [*self._threads, *workers] if thread.is_alive()]

    def _worker_started(self) -> None:
        """A pool's new worker (the calling thread) scheduled as the others are now."""
        with self._lock:
            if self.realtime and not is_realtime() and make_shared_realtime() == "":
                self._raised.add(threading.current_thread())

    def follow(self, realtime: bool) -> None:
        """The threads real-time (``realtime``: the control thread is) or ordinary."""
        with self._lock:
            if realtime == self.realtime and self.words:
                return
            self.realtime = realtime
            if not realtime:
                for thread in self._raised:
                    if thread.is_alive():
                        make_ordinary(thread.native_id or 0)
                self._raised.clear()
                self.words = "ordinary scheduling (the control thread is not real-time)"
                return
            refusals: set[str] = set()
            for thread in self._members():
                if thread in self._raised or is_realtime(thread.native_id or 0):
                    continue
                refusal = make_shared_realtime(thread.native_id or 0)
                if refusal:
                    refusals.add(refusal)
                else:
                    self._raised.add(thread)
            count = len(self._raised)
            self.words = (
                f"ordinary scheduling (SCHED_FIFO {SHARED_PRIORITY} refused: "
                f"{', '.join(sorted(refusals))})" if refusals else
                f"SCHED_FIFO {SHARED_PRIORITY}: {count} thread{'s' * (count != 1)}"
                f"{' and the callback pool' if self._pools else ''}")
