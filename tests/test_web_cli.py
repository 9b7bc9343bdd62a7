"""``teleop web`` as a user starts it: any URDF with its meshes, scenes, one-line errors."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from browser_helpers import PANDA, answer_ctrl_c, free_port

from web import cli as web_cli
from web.app import TeleopApp


def serve(*args: str, timeout: float = 90.0,
          stop: signal.Signals = signal.SIGINT) -> tuple[str, str, int]:
    """Start ``python -m web ARGS``, wait for its "on http://" line, send it ``stop``
    (Ctrl-C's SIGINT, or a service manager's SIGTERM)."""
    process = subprocess.Popen([sys.executable, "-m", "web", "--port", str(free_port()), *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=answer_ctrl_c)
    lines = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            line = process.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "Ctrl-C stops" in line:
                break
        process.send_signal(stop)
        out, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    return "".join(lines) + out, err, process.returncode


def test_the_panda_opens_with_its_meshes():
    out, err, code = serve("--robot", str(PANDA), "--ee-frame", "panda_hand",
                           "--constrained-link", "panda_link4", "--link-axis", "-0.0825", "0.384", "0")
    assert code == 0, err
    assert "panda on http://127.0.0.1:" in out
    assert "warning" not in err and "Traceback" not in err, err


def test_a_urdf_whose_meshes_are_missing_opens_with_a_warning_line_each(tmp_path):
    urdf = tmp_path / "panda.urdf"
    urdf.write_text(PANDA.read_text())  # its package:// meshes are not found from here
    out, err, code = serve("--robot", str(urdf))
    assert code == 0, err
    assert "panda on http://" in out and "Traceback" not in err
    warnings = [line for line in err.splitlines() if "warning:" in line]
    assert len(warnings) == 2 and "could not load the visual geometry" in warnings[0]


def test_a_scene_opens_with_its_robot(sda10f, tmp_path):
    app = TeleopApp(sda10f, record_dir=tmp_path, scene_dir=tmp_path)
    app.constraints.add("hole", distance=0.08)
    app.robots.set_ghost("qp:daqp")
    path = app.scenes.save("scene.json")
    args = web_cli.build_parser().parse_args(["--scene", str(path)])
    robot, scene = web_cli._load(args)
    assert robot.name == "sda10f" and scene["constraints"][0]["id"] == "hole-1"
    out, err, code = serve("--scene", str(path))
    assert code == 0, err
    assert "sda10f on http://" in out and "(controller cjm, ghost qp:daqp)" in out


@pytest.mark.parametrize("robot", ["sda10f_dual", "sda10f_dual_mobile"])
def test_the_two_arm_robots_start(robot):
    out, err, code = serve("--robot", robot)
    assert code == 0, err
    assert f"{robot} on http://" in out and err == "", err


def test_locked_joints_are_frozen_out_of_the_robot(tmp_path):
    args = web_cli.build_parser().parse_args(["--robot", "sda10f_dual",
                                              "--locked-joints", "torso_joint_b1"])
    robot, scene = web_cli._load(args)
    assert robot.nv == 14 and dict(robot.locked_joints) == {"torso_joint_b1": (0.0,)}
    app = TeleopApp(robot, record_dir=tmp_path)  # and a scene of it names the locked joint
    assert app.scenes.scene()["robot"]["locked_joints"] == {"torso_joint_b1": [0.0]}


@pytest.mark.parametrize("args, message", [
    (["--robot", "/nonexistent.urdf"], "no URDF file at '/nonexistent.urdf'"),
    (["--robot", "sda10f_dual", "--locked-joints", "elbow"],
     "locked_joints: unknown joint 'elbow'"),
    (["--scene", "/nonexistent.json"], "no scene file at '/nonexistent.json'"),
    (["--scene", "x.json", "--robot", "ur5_instrument", "--q-home=0"],
     "--scene sets the robot: drop --robot, --q-home"),
])
def test_what_cannot_be_opened_is_one_line_and_exit_2(args, message, capsys):
    assert web_cli.main(args) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err, err


def test_a_scene_file_that_is_not_a_scene_is_one_line(tmp_path, capsys):
    path = tmp_path / "s.json"
    path.write_text(json.dumps({"robot": {"source": "sda10f"}, "format": "nope"}))
    assert web_cli.main(["--scene", str(path), "--port", str(free_port())]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "not a scene file" in err, err


# -- the address: checked, loopback by default, a token beyond it -------------------------------


@pytest.mark.parametrize("args, message", [
    (["--port", "99999"], "port must be from 1 to 65535, got 99999"),
    (["--port", "0"], "port must be from 1 to 65535, got 0"),
    (["--port", "abc"], "port must be a whole number from 1 to 65535"),
    (["--host", "not a host"], "host 'not a host' is not an IP address or a host name"),
    (["--host", "8.8.8.8"], "cannot listen on 8.8.8.8 port"),
    (["--host", "0.0.0.0"], "--host 0.0.0.0 serves the UI beyond this machine: give --token"),
    (["--host", "127.0.0.1", "--token", "short"], "token must be at least 16 characters"),
    (["--rate", "1e12"], "argument --rate: must be in (0, 10000] Hz, got 1e+12"),
    (["--rate", "8000"], "rate must be between 50 and 5000 Hz"),
])
def test_an_address_or_rate_that_cannot_be_served_is_one_line_and_exit_2(args, message):
    """Run as a user would (a subprocess, bounded): one line, exit code 2, no hang."""
    result = subprocess.run([sys.executable, "-m", "web", *args], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""


def test_a_host_beyond_loopback_warns_and_prints_the_address_with_the_token():
    out, err, code = serve("--host", "0.0.0.0", "--token", "auto")
    assert code == 0, err
    warning = [line for line in err.splitlines() if "warning:" in line]
    assert len(warning) == 1 and "anyone who can reach this port and has the token can move " \
        "the robot" in warning[0] and "SSH tunnel" in warning[0], err
    assert "on http://0.0.0.0:" in out and "/?websocket=ws://0.0.0.0:" in out
    assert "/?token=" in out


def test_the_help_says_what_the_server_exposes(capsys):
    with pytest.raises(SystemExit):
        web_cli.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for words in ("--scene-dir", "--record-dir", "--token", "SSH tunnel",
                  "can move the robot, and read and write scene files"):
        assert words in text, words


def fifo_threads(pid: int) -> list[str]:
    """The threads of process ``pid`` scheduled SCHED_FIFO (policy 1 in ``/proc``'s sched)."""
    names = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            sched = (task / "sched").read_text()
        except OSError:  # the thread ended meanwhile
            continue
        policy = next(line for line in sched.splitlines() if line.startswith("policy"))
        if int(policy.split(":")[1]) == os.SCHED_FIFO:
            names.append((task / "comm").read_text().strip())
    return names


def may_run_realtime() -> bool:
    """Whether this user may schedule SCHED_FIFO (root, CAP_SYS_NICE or ``ulimit -r``)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except PermissionError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


@pytest.mark.parametrize("priority", [None, "0"])
def test_loop_priority_0_keeps_every_thread_of_the_server_ordinary(priority):
    """``--loop-priority 0``: no thread of the running server is SCHED_FIFO; the default
    makes the control thread real-time and the server's own threads with it, where this
    user may (docs/design.md 5.3)."""
    given = [] if priority is None else ["--loop-priority", priority]
    process = subprocess.Popen([sys.executable, "-m", "web", "--port", str(free_port()), *given],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=answer_ctrl_c)
    try:
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline and "Ctrl-C stops" not in process.stdout.readline():
            assert process.poll() is None, process.communicate()
        time.sleep(1.0)  # the control thread's checks (every 0.25 s) have run
        real_time = fifo_threads(process.pid)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
        assert process.returncode == 0, err
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    if priority is None and may_run_realtime():
        assert len(real_time) >= 2, real_time  # the control thread and the server's own
    else:
        assert real_time == []


def test_a_loop_priority_out_of_range_is_refused_by_name():
    result = subprocess.run([sys.executable, "-m", "web", "--loop-priority", "100"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "argument --loop-priority: must be in [0, 99], got 100" in result.stderr
