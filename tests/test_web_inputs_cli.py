"""``teleop web --input``: a network master on a UDP port of this machine, a SpaceMouse
that is not there, and what cannot be opened (one line, exit 2)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time

import pytest
from browser_helpers import answer_ctrl_c, free_port

from teleop.inputs import FeedbackState, MasterClient, UdpMaster
from web import cli as web_cli


def start(*args: str) -> tuple[subprocess.Popen, str]:
    """``python -m web ARGS`` started, and its lines up to the "Ctrl-C stops" one."""
    process = subprocess.Popen([sys.executable, "-m", "web", "--port", str(free_port()), *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=answer_ctrl_c)
    deadline = time.monotonic() + 90.0
    lines = ""
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        lines += line
        if not line or "Ctrl-C stops" in line:
            return process, lines
    return process, lines


def stop(process: subprocess.Popen) -> tuple[str, int]:
    process.send_signal(signal.SIGINT)
    try:
        _, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    return err, process.returncode


def free_udp_port() -> int:
    probe = UdpMaster(port=0)
    port = probe.port
    probe.close()
    return port


def test_a_network_master_drives_the_robot_through_the_command_line():
    port = free_udp_port()
    process, line = start("--input", f"udp:{port}")
    try:
        assert f"input udp:{port} on tool0" in line, line
        (key,) = re.findall(r"network master key ([0-9a-f]{64}) ", line)
        with MasterClient(port, key=key) as client:
            deadline = time.monotonic() + 30.0
            feedback = None
            while feedback is None or feedback.state != FeedbackState.FOLLOWING:
                assert time.monotonic() < deadline, "no feedback"
                client.send_pose((0.0, 0.0, 0.0))
                time.sleep(0.01)
                feedback = client.feedback() or feedback
            assert feedback.ee == 0 and len(feedback.wrench) == 6
    finally:
        err, code = stop(process)
    assert code == 0 and "Traceback" not in err, err


def test_spacemouse_without_a_device_is_one_warning_line_and_the_ui_runs():
    process, line = start("--input", "spacemouse")
    err, code = stop(process)
    assert "Ctrl-C stops" in line and code == 0, err
    warnings = [w for w in err.splitlines() if "warning" in w]
    assert len(warnings) == 1 and "--input spacemouse: " in warnings[0], err
    assert "the UI runs without it" in warnings[0] and "Traceback" not in err


@pytest.mark.parametrize("args, message", [
    (["--input", "serial:/dev/ttyS0"], "expected udp:PORT, ros2:NAMESPACE or spacemouse"),
    (["--input", "udp:0"], "port"),
    (["--input", "udp:9870@nowhere"], "no end effector nowhere"),
    (["--input", "udp:9870", "--input", "udp:9871@0"], "already driven by udp:9870"),
])
def test_what_cannot_be_opened_is_one_line_and_exit_2(args, message, capsys):
    assert web_cli.main(["--port", str(free_port()), *args]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err, err


@pytest.mark.parametrize("timeout", ["1", "4.9", "5001", "1e308", "nan"])
def test_an_input_timeout_beyond_the_table_is_refused_while_parsing(timeout, capsys):
    with pytest.raises(SystemExit) as exit:
        web_cli.main(["--port", str(free_port()), "--input", "udp:9870", "--input-timeout",
                      timeout])
    err = capsys.readouterr().err
    assert exit.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert "argument --input-timeout: must be in [5, 5000] ms" in err, err


def test_a_port_another_program_holds_is_one_line_and_exit_2(capsys):
    taken = UdpMaster(port=0)
    try:
        assert web_cli.main(["--port", str(free_port()), "--input", f"udp:{taken.port}"]) == 2
    finally:
        taken.close()
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"udp 127.0.0.1:{taken.port}" in err, err
