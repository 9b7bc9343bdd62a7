"""SIGTERM and SIGHUP end a command as Ctrl-C does (teleop/cli/termination.py): its
``finally`` blocks and ``atexit`` run, so a ROS 2 robot gets its zeros."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest
from test_ros2_wire import COMMANDS, STATES, CommandLog, domain, loopback, sim, wait_for

from teleop.cli.termination import TERMINATIONS, terminations_interrupt
from teleop.plants.ros2.node import Ros2Node

#: the fixtures of test_ros2_wire used here
__all__ = ["domain", "loopback"]

#: the longest wait for a started command's first command on the wire (periods of 2 ms)
STARTUP_PERIODS = 60_000



SIGNALS = (signal.SIGINT, *TERMINATIONS)


@pytest.mark.parametrize("signum", SIGNALS, ids=lambda signum: signum.name)
def test_the_first_signal_interrupts_the_block_a_second_one_not_its_cleanup(signum):
    """The first signal raises ``KeyboardInterrupt`` naming it; the same signal again
    while the cleanup runs (Ctrl-C twice) is ignored, the cleanup finishes; the handlers
    from before the block come back."""
    received = []
    cleaned = []

    def before(number: int, frame: object) -> None:  # were the block's not installed
        received.append(number)

    previous = {number: signal.signal(number, before) for number in SIGNALS}
    try:
        with pytest.raises(KeyboardInterrupt, match=f"^{signum.name}$"):
            with terminations_interrupt():
                try:
                    os.kill(os.getpid(), signum)
                    time.sleep(5.0)  # the handler runs at the next bytecode: never this long
                finally:  # the cleanup, and a second signal in its middle
                    os.kill(os.getpid(), signum)
                    time.sleep(0.05)
                    cleaned.append(True)
        assert cleaned == [True] and received == []
        assert all(signal.getsignal(number) is before for number in SIGNALS)
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


@pytest.mark.parametrize("signum", SIGNALS, ids=lambda signum: signum.name)
def test_a_signal_ignored_on_entry_stays_ignored(signum):
    """``nohup`` (SIGHUP) or a background job (SIGINT): the command keeps ignoring it."""
    previous = signal.signal(signum, signal.SIG_IGN)
    try:
        with terminations_interrupt():
            assert signal.getsignal(signum) is signal.SIG_IGN
            os.kill(os.getpid(), signum)
            time.sleep(0.05)
        assert signal.getsignal(signum) is signal.SIG_IGN
    finally:
        signal.signal(signum, previous)


def test_outside_the_main_thread_nothing_changes():
    seen = {}

    def run() -> None:
        with terminations_interrupt():
            seen["handlers"] = [signal.getsignal(signum) for signum in TERMINATIONS]

    before = [signal.getsignal(signum) for signum in TERMINATIONS]
    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    assert seen["handlers"] == before


def test_sigterm_stops_a_compare_on_a_ros2_robot_with_zeros_last(domain, tmp_path):
    """``teleop compare --plant ros2`` against ``teleop sim --ros2`` in two processes, a
    service manager's SIGTERM once the robot is commanded: exit code 130, one line saying
    so, no traceback, and zeros the last command on the wire (a ros2_control velocity
    controller holds its last command: without them the robot would go on moving)."""
    robot = sim(domain, "--robot", "ur5_instrument")
    peer = Ros2Node(domain)
    log = CommandLog(peer)
    run = subprocess.Popen(
        [sys.executable, "-m", "teleop", "compare", "--scenario", "trocar-circle", "--controllers",
         "cjm", "--plant", "ros2", "--ros-domain", str(domain), "--joint-states", STATES,
         "--command-topic", COMMANDS, "--no-plots", "--out", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # the compare's start (imports, the robot's model, DDS discovery, the first state)
        # took more than the wire's 5 s patience on a machine at load 15-20: its own bound
        commanded = wait_for(lambda: any(any(command) for command in log.poll())
                             or run.poll() is not None, periods=STARTUP_PERIODS)
        assert commanded and run.poll() is None, (
            "the compare never commanded the robot", run.poll(),
            run.communicate(timeout=60) if run.poll() is not None else "still running")
        run.send_signal(signal.SIGTERM)
        _, error = run.communicate(timeout=60)
        wait_for(lambda: not any(log.poll()[-1]))  # a wait, asserted below
        commands = log.poll()
    finally:
        if run.poll() is None:
            run.kill()
            run.communicate()
        peer.close()
        robot.terminate()
        robot.wait()
    assert run.returncode == 130, error
    assert "teleop compare: stopped (SIGTERM)" in error and "Traceback" not in error, error
    assert not any(commands[-1])
