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
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor

#: ``SCHED_FIFO``'s lowest priority: the server's threads other than the control thread
SHARED_PRIORITY = 1


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


def _worker_started() -> None:
    """A pool's new worker (the calling thread) scheduled as the server's other threads."""
    make_shared_realtime()


def share_priority(threads: Iterable[threading.Thread],
                   pools: Iterable[ThreadPoolExecutor] = ()) -> str:
    """``threads`` (running) and every worker ``pools`` start from now on scheduled by
    :func:`make_shared_realtime`; in words, how (``SCHED_FIFO 1: 5 threads``, or why
    not)."""
    threads, pools = [thread for thread in threads if thread.is_alive()], list(pools)
    refusals = {make_shared_realtime(thread.native_id or 0) for thread in threads} - {""}
    for pool in pools:  # its workers are started as callbacks come: each sets itself
        pool._initializer = _worker_started
    if refusals:
        return (f"ordinary scheduling (SCHED_FIFO {SHARED_PRIORITY} refused: "
                f"{', '.join(sorted(refusals))})")
    return (f"SCHED_FIFO {SHARED_PRIORITY}: {len(threads)} thread{'s' * (len(threads) != 1)}"
            f"{' and the callback pool' if pools else ''}")
