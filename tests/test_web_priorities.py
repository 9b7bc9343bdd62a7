"""How the server's threads are scheduled (docs/design.md section 5.3, "Priorities"): the
control thread ``SCHED_FIFO`` at its priority, given back to ordinary scheduling when its
ticks hold a CPU (not when they wait) and taken again at the next rate; the server's other threads
``SCHED_FIFO`` at the lowest priority, what they start ordinary; nothing real-time at
priority 0. (This machine runs the tests as root: the system grants the priorities.)"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest
from browser_helpers import wait_for

from teleop.inputs import UdpMaster
from web.app import ControlThread, TeleopApp
from teleop.cpu_guard import QUIET_RETAKE, SHARE as HOG_SHARE, WINDOW as HOG_WINDOW
from web.shared_priority import SHARED_PRIORITY, make_shared_realtime
from web.ui import run_server


def scheduling(thread_id: int) -> tuple[int, bool, int]:
    """The policy of kernel thread ``thread_id`` (without the flag), whether it is set
    ``SCHED_RESET_ON_FORK``, and its real-time priority."""
    policy = os.sched_getscheduler(thread_id)
    return (policy & ~os.SCHED_RESET_ON_FORK, bool(policy & os.SCHED_RESET_ON_FORK),
            os.sched_getparam(thread_id).sched_priority)


@pytest.fixture()
def app(sda10f, tmp_path):
    return TeleopApp(sda10f, controller="cjm", rate=250.0, record_dir=tmp_path,
                     scene_dir=tmp_path / "scenes")


def test_the_control_thread_runs_fifo_gives_it_up_when_it_never_sleeps_and_takes_it_again(
        app, monkeypatch):
    step = app.step
    control = ControlThread(app, realtime_priority=40)
    control.start()
    try:
        wait_for(lambda: app.ticker.ticks > 20, 10.0)
        assert scheduling(control.thread.native_id) == (os.SCHED_FIFO, True, 40)
        assert control.scheduling == "SCHED_FIFO 40"

        def waiting_step():  # 6 ms a tick at 250 Hz (4 ms), waiting: no CPU taken
            time.sleep(6e-3)
            return step()

        monkeypatch.setattr(app, "step", waiting_step)
        ticks = app.ticker.ticks
        wait_for(lambda: app.ticker.ticks > ticks + 3 * HOG_WINDOW / 6e-3, 10.0)
        assert control.scheduling == "SCHED_FIFO 40"  # three windows late, but sleeping

        def hogging_step():  # 6 ms a tick on the CPU: never time to sleep
            until = time.thread_time() + 6e-3
            while time.thread_time() < until:
                pass
            return step()

        monkeypatch.setattr(app, "step", hogging_step)
        words = wait_for(lambda: "given up" in control.scheduling and control.scheduling, 10.0)
        assert words.startswith("ordinary scheduling (SCHED_FIFO 40 given up: the ticks took ")
        assert float(words.split("took ")[1].split(" %")[0]) > 100 * HOG_SHARE
        assert scheduling(control.thread.native_id) == (os.SCHED_OTHER, False, 0)
        monkeypatch.setattr(app, "step", step)
        app.robots.set_rate(200.0)  # a new rate: real-time again
        wait_for(lambda: control.scheduling == "SCHED_FIFO 40", 10.0)
        assert scheduling(control.thread.native_id) == (os.SCHED_FIFO, True, 40)
    finally:
        control.stop()
    assert not control.alive


def test_priority_zero_leaves_the_control_thread_ordinary(app):
    control = ControlThread(app)  # 0 unless asked
    control.start()
    try:
        wait_for(lambda: app.ticker.ticks > 5, 10.0)
        assert scheduling(control.thread.native_id) == (os.SCHED_OTHER, False, 0)
        assert control.scheduling == "ordinary scheduling"
    finally:
        control.stop()


def test_a_priority_outside_0_to_99_is_refused_by_name(app):
    for priority in (-1, 100, 1.5, True):
        with pytest.raises(ValueError, match="realtime_priority must be a whole number"):
            ControlThread(app, realtime_priority=priority)


def test_a_thread_that_is_gone_is_not_scheduled_and_says_why():
    ended = threading.Thread(target=lambda: None)
    ended.start()
    thread_id = ended.native_id
    ended.join()
    words = make_shared_realtime(thread_id)
    assert words == "" or words == "No such process"  # its id may be another's by now


def ordinary_child() -> int:
    """The policy of a process started from the calling thread."""
    done = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0))"],
                          capture_output=True, text=True, timeout=60, check=True)
    return int(done.stdout)


def thread_started_here() -> tuple[int, bool, int]:
    """The scheduling of a thread started from the calling thread."""
    seen: list[tuple[int, bool, int]] = []
    child = threading.Thread(target=lambda: seen.append(scheduling(0)))
    child.start()
    child.join()
    return seen[0]


@pytest.mark.parametrize("priority", [40, 0])
def test_the_servers_other_threads_run_fifo_below_the_control_thread(sda10f, tmp_path,
                                                                     priority):
    master = UdpMaster(port=0)
    server, app, control, ui = run_server(sda10f, port=0, rate=250.0, record_dir=tmp_path,
                                          scene_dir=tmp_path / "scenes", inputs=[master],
                                          realtime_priority=priority)
    try:
        wait_for(lambda: app.ticker.ticks > 20, 20.0)
        others = {thread.name: thread for thread in threading.enumerate()}
        threads = [others["view"], others["inbox"], others[f"input {master.name}"],
                   server._websock_server._server_thread]
        pool = server._thread_executor
        in_pool = pool.submit(lambda: (scheduling(0), thread_started_here(), ordinary_child()))
        worker, started, child = in_pool.result(timeout=60)
        if priority:
            assert scheduling(control.thread.native_id) == (os.SCHED_FIFO, True, priority)
            for thread in threads:
                assert scheduling(thread.native_id) == (os.SCHED_FIFO, True, SHARED_PRIORITY), \
                    thread.name
            assert worker == (os.SCHED_FIFO, True, SHARED_PRIORITY)
            assert control.shared_scheduling.startswith(f"SCHED_FIFO {SHARED_PRIORITY}: ")
        else:
            for thread in [control.thread, *threads]:
                assert scheduling(thread.native_id) == (os.SCHED_OTHER, False, 0), thread.name
            assert worker == (os.SCHED_OTHER, False, 0)
            assert control.shared_scheduling == (
                "ordinary scheduling (the control thread is not real-time)")
        assert started == (os.SCHED_OTHER, False, 0)  # what they start runs ordinary
        assert child == os.SCHED_OTHER
        assert scheduling(0) == (os.SCHED_OTHER, False, 0)  # the caller's own untouched
    finally:
        ui.stop()
        control.stop()
        app.devices.close()
        server.stop()


def hog_cpu_then(step):
    """``step`` after 6 ms on the CPU: at 250 Hz (4 ms) never time to sleep."""
    def hogging_step():
        until = time.thread_time() + 6e-3
        while time.thread_time() < until:
            pass
        return step()
    return hogging_step


def test_the_other_threads_are_real_time_only_while_the_control_thread_is(sda10f, tmp_path,
                                                                           monkeypatch):
    """Given up, the control thread would run below FIFO 1 threads: they go ordinary with
    it and come back with it, when its ticks ran QUIET_RETAKE s under the share (no rate
    change)."""
    master = UdpMaster(port=0)
    server, app, control, ui = run_server(sda10f, port=0, rate=250.0, record_dir=tmp_path,
                                          scene_dir=tmp_path / "scenes", inputs=[master])
    try:
        wait_for(lambda: app.ticker.ticks > 20, 20.0)
        others = {thread.name: thread for thread in threading.enumerate()}
        threads = [others["view"], others["inbox"], others[f"input {master.name}"],
                   server._websock_server._server_thread]
        worker = server._thread_executor.submit(lambda: threading.current_thread()).result(60)
        threads.append(worker)
        for thread in threads:
            assert scheduling(thread.native_id) == (os.SCHED_FIFO, True, SHARED_PRIORITY), \
                thread.name
        step = app.step
        monkeypatch.setattr(app, "step", hog_cpu_then(step))
        wait_for(lambda: "given up" in control.scheduling, 10.0)
        wait_for(lambda: control.shared_scheduling.startswith("ordinary"), 2 * HOG_WINDOW + 1)
        assert scheduling(control.thread.native_id) == (os.SCHED_OTHER, False, 0)
        for thread in threads:
            assert scheduling(thread.native_id) == (os.SCHED_OTHER, False, 0), thread.name
        monkeypatch.setattr(app, "step", step)
        retaken = time.monotonic()
        wait_for(lambda: control.scheduling == "SCHED_FIFO 40", QUIET_RETAKE + 10.0)
        assert time.monotonic() - retaken >= QUIET_RETAKE - HOG_WINDOW
        wait_for(lambda: control.shared_scheduling.startswith("SCHED_FIFO"), 2 * HOG_WINDOW + 1)
        assert scheduling(control.thread.native_id) == (os.SCHED_FIFO, True, 40)
        for thread in threads:
            assert scheduling(thread.native_id) == (os.SCHED_FIFO, True, SHARED_PRIORITY), \
                thread.name
    finally:
        ui.stop()
        control.stop()
        app.devices.close()
        server.stop()


class MasterWithLibraryThreads(UdpMaster):
    """A UDP master whose start also starts two threads the server does not own: a
    library's (ordinary) and a watchdog that made itself SCHED_FIFO 40 (as the ROS 2
    plant's does)."""

    def start(self) -> None:
        super().start()
        self.stop_threads = threading.Event()
        ready = threading.Barrier(3)

        def library() -> None:
            ready.wait()
            self.stop_threads.wait()

        def watchdog() -> None:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(40))
            ready.wait()
            self.stop_threads.wait()

        self.library = threading.Thread(target=library, name="library", daemon=True)
        self.watchdog = threading.Thread(target=watchdog, name="watchdog", daemon=True)
        self.library.start()
        self.watchdog.start()
        ready.wait()


def test_only_the_servers_own_threads_are_raised_and_none_already_real_time_is_lowered(
        sda10f, tmp_path):
    master = MasterWithLibraryThreads(port=0)
    server, app, control, ui = run_server(sda10f, port=0, rate=250.0, record_dir=tmp_path,
                                          scene_dir=tmp_path / "scenes", inputs=[master])
    try:
        wait_for(lambda: app.ticker.ticks > 20, 20.0)
        assert control.shared_scheduling.startswith(f"SCHED_FIFO {SHARED_PRIORITY}: ")
        assert scheduling(master.library.native_id) == (os.SCHED_OTHER, False, 0)
        assert scheduling(master.watchdog.native_id) == (os.SCHED_FIFO, False, 40)
    finally:
        master.stop_threads.set()
        ui.stop()
        control.stop()
        app.devices.close()
        server.stop()


def test_the_heap_built_before_the_loop_starts_is_frozen_while_it_runs(app):
    """A full collection holds the GIL while it scans every tracked object (72 ms for the
    page's server): what exists when the loop starts is frozen, out of every collection's
    scan, and unfrozen when it stops."""
    import gc

    tracked = len(gc.get_objects())
    control = ControlThread(app)
    control.start()
    try:
        assert gc.get_freeze_count() >= 0.9 * tracked
        wait_for(lambda: app.ticker.ticks > 5, 10.0)
        assert len(gc.get_objects()) < 0.1 * tracked  # what a full collection scans
    finally:
        control.stop()
    assert gc.get_freeze_count() == 0
    assert len(gc.get_objects()) >= 0.9 * tracked


def test_the_control_thread_lets_its_heap_freeze_go_without_unfreezing_another_holders(app):
    """gc.freeze is the process's: a plant that froze the heap keeps it frozen after the
    control thread stops (teleop.heap_freeze); unfrozen when the plant lets go."""
    import gc

    from teleop.heap_freeze import freeze_heap, release_heap

    plant = object()
    freeze_heap(plant)
    try:
        control = ControlThread(app)
        control.start()
        wait_for(lambda: app.ticker.ticks > 5, 10.0)
        control.stop()
        assert gc.get_freeze_count() > 0
    finally:
        release_heap(plant)
    assert gc.get_freeze_count() == 0
