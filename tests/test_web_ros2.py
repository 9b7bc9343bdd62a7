"""The page drives one robot over ROS 2 (``teleop web --plant ros2``, docs/ros2.md):
``teleop sim --ros2`` in another process, the page's core (:class:`web.app.TeleopApp`)
driven headlessly in this one, real DDS on the loopback interface, a domain id per test.
Waits are counted in control periods; no wall-clock figure is asserted here."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import free_port
from test_web_cli import serve
from test_ros2_wire import COMMANDS, LOOPBACK, STATES, CommandLog, domain, loopback, robot, sim

from teleop import load_robot
from teleop.plants.choice import PlantChoice
from teleop.plants.ros2.node import Ros2Node
from teleop.plants.ros2.ros2_plant import Ros2Plant
from teleop.plants.ros2.settings import Ros2Settings
from web.app import TeleopApp
from web.app.control_thread import ControlThread

RATE = 500.0
ROOT = Path(__file__).resolve().parents[1]
#: the sim's start, away from home (the page must start where the robot is)
Q0 = load_robot("ur5_instrument").q_home + [0.1, -0.05, 0.1, 0.05, 0.05, 0.1, 0.0, 0.0]

#: the fixtures of test_ros2_wire used here (one domain counter for every ROS 2 test file)
__all__ = ["domain", "loopback", "robot"]


def settings_for(domain: int, **fields) -> Ros2Settings:
    return Ros2Settings(domain=domain, joint_states=STATES, command_topic=COMMANDS,
                        **{"start_timeout": 30.0, **fields})


@pytest.fixture
def robot_process(domain: int) -> Iterator[subprocess.Popen]:
    process = sim(domain, "--q0", ",".join(repr(float(v)) for v in Q0), "--rate", str(RATE))
    yield process
    if process.poll() is None:
        process.terminate()
    process.wait()


def hole_error(app: TeleopApp) -> float:
    """The placed constraints' largest violation at the main robot's configuration,
    computed here from Pinocchio's frames."""
    loop = app.robots.loops["main"]
    model, data = app.robot.model, app.robot.model.createData()
    pin.framesForwardKinematics(model, data, loop.q)
    return max(c.violation(data.oMf[f])
               for c, f in zip(loop.constraints, loop.controller.constraint_frames))


def hold_the_hole(app: TeleopApp) -> tuple[float, float]:
    """A hole placed where the instrument is, the target moved 2 cm sideways then 1 cm
    down: the hole's largest error over the motion and the tip's distance to its target
    at the end (m)."""
    app.constraints.add("hole", distance=0.20)
    errors = []
    for offset in ([0.0, 0.02, 0.0], [0.0, 0.0, -0.01]):
        app.console.nudge_target(offset)
        for _ in range(int(RATE)):  # one second each
            app.step()
            errors.append(hole_error(app))
    distance = float(np.linalg.norm(app.robots.loops["main"].ee_placements()[0].translation
                                    - app.console.target.translation))
    return max(errors), distance


def in_process(robot, tmp_path: Path) -> float:
    """:func:`hold_the_hole`'s hole error on the page's in-process kinematic robot, from
    the sim's start."""
    app = TeleopApp(robot, rate=RATE, record_dir=tmp_path, scene_dir=tmp_path)
    app.robots.loops["main"].q = Q0.copy()
    app.console.inputs[0].target = app.robots.loops["main"].ee_placements()[0]
    return hold_the_hole(app)[0]


def test_the_page_drives_the_simulated_robot_and_holds_the_hole(robot, domain, robot_process,
                                                                tmp_path):
    """The page starts where the robot is (the sim's q0, not home), one command writer
    whatever the operator rebuilds, the hole held as the target moves (within 0.2 mm;
    measured against the in-process kinematic plant in docs/ros2.md), the tip reaching
    the target."""
    # the watchdog at 1 s (as test_ros2_wire's closed loop): a loaded machine's 50 ms
    # pause would stop the robot, which the next test checks
    app = TeleopApp(robot, rate=RATE, plant="ros2",
                    ros2_settings=settings_for(domain, stale_after=1.0),
                    record_dir=tmp_path, scene_dir=tmp_path)
    try:
        np.testing.assert_array_equal(app.robots.loops["main"].q, Q0)  # float64 on the wire
        plant = app.robots.loops["main"].plant
        assert isinstance(plant, Ros2Plant)
        app.robots.set_controller("qp:daqp")
        app.robots.set_rate(250.0)
        assert app.robots.loops["main"].plant is plant and plant.dt == pytest.approx(4e-3)
        app.robots.set_rate(RATE)
        assert plant.dt == pytest.approx(1.0 / RATE)
        with pytest.raises(ValueError, match="no ghost .* one robot over ROS 2"):
            app.robots.set_ghost("cjm")
        assert list(app.robots.loops) == ["main"]
        app.robots.set_controller("cjm")
        error, distance = hold_the_hole(app)
        measures = plant.measures()
        assert measures.stopped == "" and measures.command_publishers == 1
        assert app.view.limitation().words.find("stopped") < 0
    finally:
        (app.ros2 or pytest.fail("no ROS 2 robot")).close()
    reference = in_process(robot, tmp_path)
    print(f"hole error over DDS {error * 1e6:.3f} um; in process {reference * 1e6:.3f} um "
          f"({error / reference:.2f}x); tip {distance * 1e3:.2f} mm from the target")
    assert 0 < error < 2e-4
    assert distance < 1e-3


def test_the_status_says_why_the_robot_stopped(robot, domain, robot_process, tmp_path):
    """The simulated robot killed: the watchdog stops the robot (zeros on the command
    topic) and the page's status says why, by name. Its deadline is 0.3 s here, not the
    default 50 ms: on a loaded machine the sim itself pauses for longer than 50 ms now and
    then (70 ms seen), which stopped the robot before the kill (the watchdog's own time is
    measured in the timing tier)."""
    peer = Ros2Node(domain)
    log = CommandLog(peer)
    app = TeleopApp(robot, rate=RATE, plant="ros2",
                    ros2_settings=settings_for(domain, stale_after=0.3),
                    record_dir=tmp_path, scene_dir=tmp_path)
    try:
        app.console.nudge_target([0.0, 0.01, 0.0])
        for _ in range(100):
            app.step()
        assert "stopped" not in app.view.limitation().words
        robot_process.send_signal(signal.SIGKILL)
        robot_process.wait()
        for _ in range(int(2 * RATE)):
            app.step()
        words = app.view.limitation().words
        assert "the ROS 2 robot is stopped (joint states stale" in words, words
        assert log.poll() and not any(log.poll()[-1])  # zeros last
    finally:
        (app.ros2 or pytest.fail("no ROS 2 robot")).close()
        peer.close()


@pytest.mark.timing
def test_the_hole_over_dds_within_2x_of_in_process(robot, domain, robot_process, tmp_path):
    """The issue's target (docs/ros2.md "Measured"): the page over DDS holds the hole within
    2x of the page on the in-process kinematic robot, no latency (the plant moves the state
    on by the command in flight, ``command_latency`` 1). Timing: the two processes' period
    jitter adds to the error on a loaded machine (an idle one needed)."""
    app = TeleopApp(robot, rate=RATE, plant="ros2", ros2_settings=settings_for(domain),
                    record_dir=tmp_path, scene_dir=tmp_path)
    try:
        error, _ = hold_the_hole(app)
    finally:
        (app.ros2 or pytest.fail("no ROS 2 robot")).close()
    reference = in_process(robot, tmp_path)
    print(f"hole error over DDS {error * 1e6:.3f} um, in process {reference * 1e6:.3f} um: "
          f"{error / reference:.2f}x")
    assert error <= 2.0 * reference


def drive_with_the_control_thread(app: TeleopApp, drag: bool) -> tuple[float, float, list]:
    """The page's control thread running (the robot's clock pacing it, :meth:`pace`
    outside the app's lock); a hole placed where the instrument is, then the gizmo
    dragged 2 cm sideways in 200 steps of 0.1 mm, 10 ms apart, each call's duration
    kept (the lock's wait included), then 1 s to settle when ``drag``; else the target
    nudged 2 cm and 2 s. The hole's largest error sampled every step, the tip's distance
    to its target at the end (m), the calls' durations (s)."""
    app.constraints.add("hole", distance=0.20)
    control = ControlThread(app)
    control.start()
    errors, calls = [], []
    try:
        start = app.console.inputs[0].target.translation.copy()
        for i in range(1, 201) if drag else ():
            began = time.perf_counter()
            app.console.move_gizmo(start + [0.0, 1e-4 * i, 0.0], [1.0, 0.0, 0.0, 0.0])
            calls.append(time.perf_counter() - began)
            time.sleep(0.01)
            with app._lock:
                errors.append(hole_error(app))
        if not drag:
            app.console.nudge_target([0.0, 0.02, 0.0])
        for _ in range(100 if drag else 200):
            time.sleep(0.01)
            with app._lock:
                errors.append(hole_error(app))
        assert control.error is None, control.error
    finally:
        control.stop()
    distance = float(np.linalg.norm(app.robots.loops["main"].ee_placements()[0].translation
                                    - app.console.target.translation))
    return max(errors), distance, calls


def test_the_control_thread_is_paced_by_the_robot_and_holds_the_hole(robot, domain,
                                                                    robot_process, tmp_path):
    """The page's own control thread on the ROS 2 robot (its ticks paced by the robot's
    states, :meth:`Ros2Plant.pace` outside the app's lock): the target nudged 2 cm, the
    hole held (within 0.2 mm, as with the ticks called directly) and the tip reaching the
    target; the robot never stopped."""
    app = TeleopApp(robot, rate=RATE, plant="ros2",
                    ros2_settings=settings_for(domain, stale_after=1.0),
                    record_dir=tmp_path, scene_dir=tmp_path)
    try:
        error, distance, _ = drive_with_the_control_thread(app, drag=False)
        assert app.robots.loops["main"].plant.measures().stopped == ""
    finally:
        (app.ros2 or pytest.fail("no ROS 2 robot")).close()
    print(f"hole error {error * 1e6:.3f} um, tip {distance * 1e3:.2f} mm from the target")
    assert 0 < error < 2e-4
    assert distance < 1e-3


@pytest.mark.timing
def test_a_drag_is_not_held_up_by_the_robots_period(robot, domain, robot_process, tmp_path):
    """The brief's measure of the page's responsiveness: a drag's call while the control
    thread runs on the ROS 2 robot returns within 5 ms at p99 (the tick waits for the robot
    outside the app's lock; when it waited inside, with the control thread real-time, p99
    was 316 ms and the worst 2.3 s at load 14: docs/ros2.md "The page over ROS 2")."""
    app = TeleopApp(robot, rate=RATE, plant="ros2",
                    ros2_settings=settings_for(domain, stale_after=1.0),
                    record_dir=tmp_path, scene_dir=tmp_path)
    try:
        error, distance, calls = drive_with_the_control_thread(app, drag=True)
    finally:
        (app.ros2 or pytest.fail("no ROS 2 robot")).close()
    p50, p99 = np.percentile(calls, [50, 99]) * 1e3
    print(f"drag call p50 {p50:.3f} ms, p99 {p99:.3f} ms, worst {max(calls) * 1e3:.3f} ms; "
          f"hole error {error * 1e6:.3f} um, tip {distance * 1e3:.2f} mm from the target")
    assert p99 <= 5.0


@pytest.mark.parametrize(("args", "message"), [
    (["--joint-states", "/js"], "--joint-states needs --plant ros2"),
    (["--plant", "mujoco", "--crtk", "/PSM1"], "--crtk needs --plant ros2"),
    (["--plant", "ros2", "--payload", "1"], "--payload needs --plant mujoco"),
    (["--plant", "ros2", "--ros-domain", "300"], "must be in [0, 232], got 300"),
    (["--plant", "ros2", "--joint-states", "bad topic"], "bad topic"),
])
def test_bad_ros2_options_are_one_line_and_exit_2(args, message, capsys):
    from web import cli as web_cli

    try:
        code = web_cli.main([*args, "--port", str(free_port())])
    except SystemExit as exit_:
        code = exit_.code
    assert code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err, err


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP],
                         ids=lambda stop: stop.name)
def test_teleop_web_plant_ros2_serves_the_robot_and_stops_it_at_exit(domain, robot_process,
                                                                      stop):
    """``python -m web --plant ros2`` against ``teleop sim --ros2``, two processes: its
    start line names the ROS 2 robot, its control thread commands the robot; Ctrl-C, a
    service manager's SIGTERM or a closed terminal's SIGHUP ends it with exit code 0 and
    zeros last on the command topic (a velocity controller holds the last command)."""
    peer = Ros2Node(domain)
    log = CommandLog(peer)
    try:
        out, err, code = serve("--robot", "ur5_instrument", "--rate", str(RATE), "--plant",
                               "ros2", "--ros-domain", str(domain), "--joint-states", STATES,
                               "--command-topic", COMMANDS, stop=stop)
        assert code == 0, err
        assert (f"(controller cjm), on the ROS 2 robot ({STATES} -> {COMMANDS}, domain "
                f"{domain}, stopped when the state is 50 ms old, response time 7.96 ms); "
                "Ctrl-C stops") in out, out
        assert "Traceback" not in err, err
        for _ in range(500):
            if log.poll() and not any(log.poll()[-1]):
                break
            time.sleep(1.0 / RATE)  # a wait counted in periods, not asserted
        commands = log.poll()
        assert len(commands) > 1 and not any(commands[-1])
    finally:
        peer.close()


def test_teleop_web_plant_ros2_refuses_a_ghost_and_a_silent_robot(domain):
    """``teleop web --plant ros2 --ghost qp``: refused by name; no robot on the topic:
    refused naming the topic once the start timeout passes (no page served)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "CYCLONEDDS_URI": LOOPBACK}
    base = [sys.executable, "-m", "teleop", "web", "--robot", "ur5_instrument", "--plant",
            "ros2", "--ros-domain", str(domain), "--joint-states", STATES + "_none",
            "--port", str(free_port())]
    ghost = subprocess.run([*base, "--ghost", "qp:daqp"], capture_output=True, text=True,
                           env=env, cwd=ROOT, timeout=120)
    assert ghost.returncode == 2 and "no ghost (qp:daqp) on the ros2 plant" in ghost.stderr
    silent = subprocess.run(base, capture_output=True, text=True, env=env, cwd=ROOT,
                            timeout=120)
    assert silent.returncode == 2 and f"no joint state on {STATES}_none" in silent.stderr
    assert len(silent.stderr.strip().splitlines()) == 1, silent.stderr


def nudged_hole_error(app: TeleopApp, seconds: float) -> float:
    """The largest error of the page's one hole (Pinocchio, at the robot's configuration
    each period) while the target moves 2 cm sideways."""
    app.console.nudge_target([0.0, 0.02, 0.0])
    errors = []
    for _ in range(int(seconds * RATE)):
        app.step()
        errors.append(hole_error(app))
    return max(errors)


@pytest.mark.timing
def test_the_page_holds_a_hole_on_the_mujoco_robot_as_in_process(robot, domain, tmp_path):
    """The same physics on both sides: a scene saved from the page (a hole 8 cm down the
    instrument) opened in ``teleop sim --ros2 --plant mujoco --scene`` (its wall acts) and
    in the page over ROS 2, the target moved 2 cm sideways: the hole's error within 2x of
    the page on the in-process MuJoCo robot with the same scene. A timing test: the ratio
    follows the two processes' jitter (docs/ros2.md "Jitter, and the commands in flight";
    measured 1.07-1.27x in five runs at load 2-3)."""
    import json

    saved = TeleopApp(robot, rate=RATE, record_dir=tmp_path, scene_dir=tmp_path)
    saved.constraints.add("hole", distance=0.08)
    scene = saved.scenes.scene()
    path = tmp_path / "hole.json"
    path.write_text(json.dumps(scene))
    process = sim(domain, "--plant", "mujoco", "--scene", str(path), "--rate", str(RATE))
    try:
        app = TeleopApp(robot, rate=RATE, plant="ros2",  # a starved sim is not stopped
                        ros2_settings=settings_for(domain, stale_after=0.25),
                        record_dir=tmp_path, scene_dir=tmp_path)
        try:
            app.scenes.apply(scene)
            over_dds = nudged_hole_error(app, 1.0)
            assert app.robots.loops["main"].plant.measures().stopped == ""
        finally:
            (app.ros2 or pytest.fail("no ROS 2 robot")).close()
    finally:
        process.terminate()
        process.wait()
    in_process = TeleopApp(robot, rate=RATE, plant="mujoco", record_dir=tmp_path,
                           scene_dir=tmp_path)
    in_process.scenes.apply(scene)
    reference = nudged_hole_error(in_process, 1.0)
    print(f"hole error over DDS {over_dds * 1e6:.2f} um, in-process MuJoCo "
          f"{reference * 1e6:.2f} um ({over_dds / reference:.2f}x)")
    assert 0.0 < over_dds <= 2.0 * reference


def test_a_failing_pace_is_the_control_threads_error_not_its_silent_end(robot, domain,
                                                                       robot_process, tmp_path):
    """The robot's plant closed under the running control thread: its :meth:`pace` raises
    (the node is gone), and the thread says so (``error``) and keeps running (the page
    shows why rather than freezing)."""
    app = TeleopApp(robot, rate=RATE, plant="ros2", ros2_settings=settings_for(domain),
                    record_dir=tmp_path, scene_dir=tmp_path)
    ros2 = app.ros2 or pytest.fail("no ROS 2 robot")
    control = ControlThread(app)
    control.start()
    try:
        ros2.close()
        for _ in range(500):
            if control.error is not None:
                break
            time.sleep(0.01)
        assert control.error is not None
        assert control.alive
    finally:
        control.stop()
        ros2.close()


def test_the_damper_counts_on_the_ros2_robots_response_time(robot, domain, robot_process,
                                                            tmp_path):
    """Over real DDS, the page's collision damper counts on ``--response-time``
    (``Ros2Settings.response_time``, docs/ros2.md) as on the MuJoCo plant's servos: every
    row of a sphere 2.5 cm in front of the tip holds the gap ``tau`` ahead,
    ``d_dot >= -(xi / (d_i - d_s)) (d - d_s + tau d_dot)`` (written here), the controller's
    damper is that one while the robot is driven, and a saved scene keeps ``tau``."""
    tau = 0.03
    app = TeleopApp(robot, rate=RATE, plant="ros2",
                    ros2_settings=settings_for(domain, stale_after=1.0, response_time=tau),
                    record_dir=tmp_path, scene_dir=tmp_path)
    try:
        tip = app.robots.loops["main"].ee_placements()[0]
        app.collisions.add("sphere", center=tip.translation + 0.065 * tip.rotation[:, 2])
        app.collisions.set_on(True)
        for _ in range(int(RATE) // 10):
            app.step()
        avoidance = app.collisions.avoidance
        assert app.robots.loops["main"].controller.collisions is avoidance
        assert app.robots.loops["main"].plant.measures().stopped == ""
        q = app.robots.loops["main"].q.copy()
    finally:
        (app.ros2 or pytest.fail("no ROS 2 robot")).close()
    xi, d_i, d_s = 0.5, 0.05, 0.005  # the defaults, written out
    assert (avoidance.approach_speed, avoidance.detection_distance,
            avoidance.safety_distance) == (xi, d_i, d_s)
    assert avoidance.response_time == tau
    assert avoidance.gain == pytest.approx(1.0 / ((d_i - d_s) / xi + tau), rel=1e-12)
    model, data = robot.model, robot.model.createData()
    pin.computeJointJacobians(model, data, q)
    rows = avoidance.rows(model, data)
    assert rows.size >= 1
    held_ahead = -(xi / (d_i - d_s)) * (rows.distances - d_s + tau * rows.lower)
    np.testing.assert_allclose(rows.lower, held_ahead, rtol=1e-12, atol=1e-18)
    saved = json.loads(app.scenes.save("late.json").read_text())
    assert saved["collisions"]["response_time"] == tau


def test_a_ros2_plants_response_time_is_the_options_else_a_20_hz_servos():
    """``--response-time`` sets the ROS 2 plant's ``tau`` wherever a plant is parsed (the
    ``teleop`` commands' plant options, ``teleop web``'s); left out, a 20 Hz servo's time
    constant (written here), the MuJoCo plant's default; refused by name out of range."""
    from teleop.cli.main import build_parser
    from teleop.cli.plant_options import plant_choice
    from web import cli as web_cli

    compare = ["compare", "--scenario", "paper-hole", "--plant", "ros2"]
    parser = build_parser()
    assert plant_choice(parser.parse_args([*compare, "--response-time", "0.02"])
                        ).response_time == 0.02
    servo = 1.0 / (2.0 * math.pi * 20.0)
    assert plant_choice(parser.parse_args(compare)).response_time == pytest.approx(servo,
                                                                                   rel=1e-15)
    assert PlantChoice("ros2").response_time == PlantChoice("mujoco").response_time
    web = web_cli._plant(web_cli.build_parser().parse_args(["--plant", "ros2",
                                                             "--response-time", "0"]))
    assert web["ros2_settings"].response_time == 0.0
    with pytest.raises(ValueError, match="response_time must be"):
        Ros2Settings(response_time=-0.1)
    with pytest.raises(ValueError, match="response_time must be"):
        Ros2Settings.from_dict({"response_time": float("nan")})
