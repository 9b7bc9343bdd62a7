"""The control thread: :meth:`web.app.TeleopApp.step` at the control rate, its timing
measured, scheduled real-time (docs/design.md section 5.3). It never touches viser."""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from teleop.cpu_guard import QUIET_RETAKE, SHARE, CpuGuard, Verdict
from teleop.heap_freeze import freeze_heap, release_heap
from teleop.plants.ros2.realtime import (check_priority, hold_realtime, release_realtime,
                                        scheduling_words)

from ..shared_priority import SharedPriority, is_realtime
from .core import TeleopApp
from .status import behind_words

#: ticks of timing kept by the control thread (a few seconds at 1 kHz)
TIMING_WINDOW = 4096
#: the control thread asks the interpreter to switch threads this often (s): a thread
#: waking for its deadline waits at most about this long for the others (Python's default
#: 5 ms would make the 1 kHz loop late by up to 5 periods whenever the view thread works)
SWITCH_INTERVAL = 2e-4


def percentiles(columns: np.ndarray, q: float) -> np.ndarray:
    """The ``q``-th percentile of each row of ``columns``, as ``np.percentile(columns, q,
    axis=1)`` computes it (linear between the two nearest order statistics), from one
    partial sort: the view thread computes these, and it shares the interpreter with the
    control thread."""
    n = columns.shape[1]
    index = q / 100.0 * (n - 1)
    below = math.floor(index)
    above = min(below + 1, n - 1)
    ordered = np.partition(columns, (below, above), axis=1)
    low, high = ordered[:, below], ordered[:, above]
    return low + (high - low) * (index - below)


@dataclass(frozen=True)
class Timing:
    """The control thread's timing over its last :data:`TIMING_WINDOW` ticks."""

    achieved_rate: float  # Hz, over the last second
    lateness_p50_ms: float  # how late a tick starts after its deadline
    lateness_p99_ms: float
    tick_p50_us: float  # the whole tick (TeleopApp.step)
    tick_p99_us: float
    overhead_p50_us: float  # the tick minus the controllers' own solve time
    deadline_misses: int
    ticks: int
    #: ticks started less than a period after their deadline, over the ticks due in the
    #: window (those skipped by a resynchronisation count as late)
    on_time: float = math.nan
    #: the tick's median parts (us): the controllers' steps; the loops' hot path beyond
    #: them (TeleopLoop.advance: targets, kinematics, twists, integration); the UI's own
    #: (the tick beyond the loops' hot path: the lock, the bookkeeping, the measures of a
    #: history tick)
    solve_p50_us: float = math.nan
    loop_p50_us: float = math.nan
    ui_p50_us: float = math.nan


class ControlThread:
    """Runs :meth:`TeleopApp.step` at the app's control rate on its own thread.

    Tracks the achieved rate, each tick's lateness (start minus deadline) and cost, and
    deadline misses (a tick that started later than one period after it was due). Sleeps
    between ticks; when it falls behind it does not try to catch up by bursting (the robot
    would see a jump), it resynchronises.

    It runs ``SCHED_FIFO`` at ``realtime_priority`` (1-99; 0: ordinary scheduling), as a
    robot's control loop does: on a loaded machine an ordinary thread waits for a CPU
    behind every other process, most of a second at a time (docs/inputs.md, "Floods").
    A thread that never sleeps would hold its core against every ordinary one: its
    :class:`~teleop.cpu_guard.CpuGuard` gives real-time up when its ticks took more than
    :data:`~teleop.cpu_guard.SHARE` of a CPU over a window, until the rate changes or its
    ticks ran :data:`~teleop.cpu_guard.QUIET_RETAKE` s under that share. The server's
    other threads (:attr:`shared`) are real-time exactly while this thread is: it makes
    them follow at every window. Over ROS 2 the plant makes the thread real-time as it
    actuates (:class:`teleop.plants.ros2.ros2_plant.Ros2Plant`, at its settings'
    priority) and this thread takes no hold of its own. Without the privilege it stays
    ordinary; :attr:`scheduling` says how it runs and why.
    """

    def __init__(self, app: TeleopApp, realtime_priority: int = 0) -> None:
        self.app = app
        self.realtime_priority = check_priority(realtime_priority)
        #: how the thread is scheduled, in words (``SCHED_FIFO 40``; why not, when not)
        self.scheduling = "not started"
        #: the server's other threads, real-time while this one is (None: none given)
        self.shared: SharedPriority | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="control", daemon=True)
        self.deadline_misses = 0
        self.achieved_rate = 0.0
        self._measured_rate: float | None = None  # the rate the last full second ran at
        self.error: str | None = None
        self._lateness = np.zeros(TIMING_WINDOW)
        self._tick = np.zeros(TIMING_WINDOW)
        self._solve = np.zeros(TIMING_WINDOW)
        self._advance = np.zeros(TIMING_WINDOW)
        self._start = np.zeros(TIMING_WINDOW)
        self._count = 0
        self._switch_interval: float | None = None

    def start(self) -> None:
        """Start ticking. What the process holds by now (the robot, the controllers, the
        server) is collected once and frozen (``gc.freeze``): Python's full collection
        holds the GIL while it scans every tracked object, 72 ms for the page's server
        (135,000 objects), which the control thread waited out; frozen, the collections
        scan only what came after. :meth:`stop` lets its freeze go (:mod:`teleop.heap_freeze`:
        the heap is unfrozen when no other holder, such as a ROS 2 plant, keeps it)."""
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch_interval, SWITCH_INTERVAL))
        freeze_heap(self)
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._thread.join(timeout)
        if self._switch_interval is not None:
            sys.setswitchinterval(self._switch_interval)
            self._switch_interval = None
            release_heap(self)

    @property
    def shared_scheduling(self) -> str:
        """How the server's other threads are scheduled, in words ("": as they were;
        :mod:`web.shared_priority`)."""
        return "" if self.shared is None else self.shared.words

    def _follow(self) -> None:
        """The server's other threads real-time exactly while this (calling) one is."""
        if self.shared is not None:
            self.shared.follow(is_realtime())

    @property
    def thread(self) -> threading.Thread:
        """The thread that ticks."""
        return self._thread

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def behind(self) -> str:
        """:func:`behind_words` for the last full second at the current rate (``""``
        before one has been measured)."""
        rate = 1.0 / self.app.robots.config.dt
        if self._measured_rate is None or self._measured_rate != rate:
            return ""
        return behind_words(self.achieved_rate, rate)

    def timing(self) -> Timing:
        """Percentiles of the recent ticks (computed here, off the control thread)."""
        n = min(self._count, TIMING_WINDOW)
        if n == 0:
            return Timing(self.achieved_rate, math.nan, math.nan, math.nan, math.nan,
                          math.nan, self.deadline_misses, 0)
        lateness, tick = self._lateness[:n].copy(), 1e6 * self._tick[:n]
        solve, advance = self._solve[:n].copy(), self._advance[:n].copy()
        period = self.app.robots.config.dt
        starts = self._start[:n].copy()
        due = max(n, round((float(starts.max() - starts.min()) + period) / period))
        columns = np.stack([1e3 * lateness, tick, tick - solve, solve, advance - solve,
                            tick - advance])
        late_50, tick_50, overhead_50, solve_50, loop_50, ui_50 = percentiles(columns, 50).tolist()
        late_99, tick_99 = percentiles(columns[:2], 99).tolist()
        return Timing(
            achieved_rate=self.achieved_rate, lateness_p50_ms=late_50, lateness_p99_ms=late_99,
            tick_p50_us=tick_50, tick_p99_us=tick_99, overhead_p50_us=overhead_50,
            deadline_misses=self.deadline_misses, ticks=self._count,
            on_time=float(np.sum(lateness < period)) / due,
            solve_p50_us=solve_50, loop_p50_us=loop_50, ui_p50_us=ui_50)

    def _run(self) -> None:
        held: int | None = None  # the thread's id while this thread holds it real-time
        try:
            held = self._loop()
        finally:
            if held is not None:
                release_realtime(held)

    def _hold(self) -> int | None:
        """The calling thread made real-time at :attr:`realtime_priority` (not over ROS 2,
        whose plant does it); the id to release, None when it took no hold."""
        if self.realtime_priority == 0 or self.app.ros2 is not None:
            self.scheduling = scheduling_words()
            return None
        held, self.scheduling = hold_realtime(self.realtime_priority)
        return held

    def _loop(self) -> int | None:
        """Ticks until stopped; the thread's real-time hold still in force (its id), if any."""
        held = self._hold()
        self._follow()
        guard = CpuGuard()
        clock = time.perf_counter
        next_tick = clock()
        window_start, window_ticks = clock(), 0
        period = self.app.robots.config.dt
        while not self._stop.is_set():
            if self.app.robots.config.dt != period:  # a new rate: a new measuring window
                period = self.app.robots.config.dt
                window_start, window_ticks = clock(), 0
                if guard.given_up:  # real-time again
                    held = self._hold()
                    guard.taken_again()
                    self._follow()
                guard.restart()
            start = clock()
            solve_us = advance_us = 0.0
            try:
                if self.app.ros2 is not None:  # the robot's clock paces the ticks: its next
                    self.app.ros2.pace()        # state awaited here, outside the app's lock
                    start = clock()
                solve_us = self.app.step()
                advance_us = self.app.advance_us
            except Exception as error:  # keep the robot still and say why
                self.error = f"{type(error).__name__}: {error}"
                time.sleep(0.01)
            end = clock()
            slot = self._count % TIMING_WINDOW
            self._lateness[slot] = max(0.0, start - next_tick)
            self._tick[slot] = end - start
            self._solve[slot] = solve_us
            self._advance[slot] = advance_us
            self._start[slot] = start
            self._count += 1
            window_ticks += 1
            if end - window_start >= 1.0:
                self.achieved_rate = window_ticks / (end - window_start)
                self._measured_rate = 1.0 / period
                window_start, window_ticks = end, 0
            verdict = guard.check(held is not None)
            if verdict is Verdict.GIVE_UP and held is not None:
                release_realtime(held)
                held = None
                self.scheduling = (
                    f"{scheduling_words()} (SCHED_FIFO {self.realtime_priority} given "
                    f"up: the ticks took {100 * guard.share:.0f} % of a CPU; again after "
                    f"{QUIET_RETAKE:g} s under {100 * SHARE:.0f} % or at the next rate)")
            elif verdict is Verdict.RETAKE:
                held = self._hold()
            if verdict is not Verdict.MID_WINDOW:
                self._follow()
            next_tick += period
            delay = next_tick - clock()
            if delay > 0 and self.app.ros2 is None:
                time.sleep(delay)
            elif delay < -period:
                self.deadline_misses += 1
                next_tick = clock()
        return held
