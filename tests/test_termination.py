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


@pytest.mark.parametrize("signum", TERMINATIONS, ids=lambda signum: signum.name)
def test_a_termination_interrupts_the_block_and_the_handler_comes_back(signum):
    received = []

    def before(number: int, frame: object) -> None:  # were the block's not installed
        received.append(number)

    previous = signal.signal(signum, before)
    try:
        with pytest.raises(KeyboardInterrupt, match=signum.name):
            with terminations_interrupt():
                os.kill(os.getpid(), signum)
                time.sleep(5.0)  # the handler runs at the next bytecode: never this long
        assert signal.getsignal(signum) is before and received == []
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
        assert wait_for(lambda: any(any(command) for command in log.poll())), \
            "the compare never commanded the robot"
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
