"""The local engine: a pool of worker processes, one cell each at a time (docs/sweep.md).

Each worker is a ``spawn``ed process (a fresh interpreter: no state shared with the driver,
the same in every worker) with single-threaded BLAS, so two workers on two cores do not
fight over them. The driver gives each idle worker the next cell and waits on the workers'
pipes and process sentinels at once:

* a worker that dies (killed, out of memory, a crash in native code) is replaced at once
  and its cell runs again, up to ``retries`` more times;
* a cell still running ``grace`` seconds past its own time limit (stuck in native code,
  where it cannot check its clock) has its worker killed and is failed with that reason.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Iterator

from .cell import FAILED, run_cell
from .spec import Cell

#: Seconds a cell may run past its time limit before its worker is killed.
GRACE_S = 30.0

#: The threads of the numerical libraries in each worker (a worker per core).
SINGLE_THREADED = {name: "1" for name in (
    "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")}


#: ``prctl`` option: the signal the kernel sends this process when its parent dies
PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """Have the kernel kill this process when the process that started it dies (Linux's
    parent-death signal), so a driver killed with SIGKILL leaves no worker running its cell
    to the end; the parent already gone is the same. Elsewhere, nothing: a worker there ends
    at its next read of the closed pipe."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:
        os._exit(1)


def _serve(connection: multiprocessing.connection.Connection, parent: int) -> None:
    """A worker's life: run each cell it is sent, send back its outcome; None ends it."""
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle
    while True:
        task = connection.recv()
        if task is None:
            return
        key, inputs, time_limit = task
        connection.send((key, run_cell(inputs, time_limit)))


@dataclass
class Finished:
    """A cell's end as an engine reports it: the cell, its outcome, the attempts it took
    and the time between the worker's previous cell and this one's start (s; None for a
    worker's first cell): the engine's overhead per cell."""

    cell: Cell
    outcome: dict[str, Any]
    attempts: int
    dispatch_gap_s: float | None = None


@dataclass
class _Worker:
    process: Any
    connection: multiprocessing.connection.Connection
    cell: Cell | None = None
    attempts: int = 0
    started: float = 0.0
    last_end: float | None = None


class LocalPool:
    """``workers`` processes running cells; :meth:`run` yields each cell's end as it comes."""

    def __init__(self, workers: int, retries: int = 2, grace: float = GRACE_S) -> None:
        self.workers, self.retries, self.grace = workers, retries, grace
        self._context = multiprocessing.get_context("spawn")
        self._pool: list[_Worker] = []

    def _start(self) -> _Worker:
        driver_end, worker_end = self._context.Pipe()
        previous = {name: os.environ.get(name) for name in SINGLE_THREADED}
        os.environ.update(SINGLE_THREADED)  # inherited by the spawned interpreter
        try:
            process = self._context.Process(target=_serve, args=(worker_end, os.getpid()), daemon=True,
                                            name="teleop-sweep-worker")
            process.start()
        finally:
            for name, value in previous.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value
        worker_end.close()
        return _Worker(process, driver_end)

    @staticmethod
    def _stop(worker: _Worker) -> None:
        if worker.process.is_alive():
            worker.process.kill()
        worker.process.join(timeout=5.0)
        worker.connection.close()

    def running(self) -> dict[str, int]:
        """The cells running now: each key with its worker's process id (to watch or
        signal a worker, as the tests do)."""
        return {w.cell.key: w.process.pid for w in self._pool if w.cell is not None}

    def run(self, cells: list[Cell], time_limit: float,
            on_start: Callable[[Cell], None] | None = None) -> Iterator[Finished]:
        """Run ``cells``; yields each one's :class:`Finished` in the order they end. Closing
        the iterator (or an exception in the caller) kills the workers: the cells in flight
        are lost, to be run on resume."""
        queue: deque[tuple[Cell, int]] = deque((cell, 0) for cell in cells)
        self._pool = [self._start() for _ in range(min(self.workers, len(cells)))]
        try:
            while queue or any(w.cell is not None for w in self._pool):
                for index, worker in enumerate(self._pool):
                    if worker.cell is None and queue:
                        if not worker.process.is_alive():  # died idle: a fresh one
                            self._stop(worker)
                            worker = self._pool[index] = self._start()
                        self._give(worker, *queue.popleft(), time_limit, on_start)
                busy = [w for w in self._pool if w.cell is not None]
                waitables = [w.connection for w in busy] + [w.process.sentinel for w in busy]
                ready = set(multiprocessing.connection.wait(waitables, timeout=1.0))
                for worker in busy:
                    if worker.connection in ready:
                        finished = self._receive(worker)
                        if finished is not None:
                            yield finished
                            continue
                    if worker.process.sentinel in ready or not worker.process.is_alive():
                        yield from self._replace(worker, queue, "its worker died "
                                                 f"(exit code {worker.process.exitcode})")
                    elif time.monotonic() > worker.started + time_limit + self.grace:
                        yield from self._replace(
                            worker, queue, f"time limit {time_limit:g} s exceeded and no "
                            f"answer {self.grace:g} s later: its worker was killed",
                            retry=False)
        finally:  # every worker killed first, then each awaited: their ends overlap
            for worker in self._pool:
                if worker.process.is_alive():
                    worker.process.kill()
            for worker in self._pool:
                self._stop(worker)
            self._pool = []

    def _give(self, worker: _Worker, cell: Cell, attempts: int, time_limit: float,
              on_start: Callable[[Cell], None] | None) -> None:
        worker.cell, worker.attempts = cell, attempts + 1
        worker.started = time.monotonic()
        try:
            worker.connection.send((cell.key, cell.inputs, time_limit))
        except OSError:  # it died meanwhile: its sentinel says so, the cell runs again
            return
        if on_start is not None:
            on_start(cell)

    def _receive(self, worker: _Worker) -> Finished | None:
        """The outcome the worker sent, or None when it died before sending it."""
        try:
            key, outcome = worker.connection.recv()
        except (EOFError, OSError):
            return None
        cell = worker.cell
        gap = None if worker.last_end is None else worker.started - worker.last_end
        worker.cell, worker.last_end = None, time.monotonic()
        return Finished(cell, outcome, worker.attempts, gap)

    def _replace(self, worker: _Worker, queue: deque, reason: str,
                 retry: bool = True) -> Iterator[Finished]:
        """Replace a dead or stuck worker; run its cell again or fail it."""
        cell, attempts = worker.cell, worker.attempts
        self._stop(worker)
        index = self._pool.index(worker)
        self._pool[index] = self._start()
        if retry and attempts <= self.retries:
            queue.appendleft((cell, attempts))
            return
        yield Finished(cell, {"status": FAILED, "reason": f"{reason} "
                              f"(attempt {attempts} of {self.retries + 1})", "metrics": None,
                              "elapsed_s": time.monotonic() - worker.started}, attempts)
