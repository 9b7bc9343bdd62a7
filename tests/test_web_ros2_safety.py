"""A real robot on the page never jumps (``teleop web --plant ros2``, docs/ros2.md):
opening a scene and Home start from where the robot is. ``teleop sim --ros2`` in another
process, the page's core headless in this one, real DDS on loopback (the fixtures of
``test_web_ros2``); the robot's motion is measured from its published joint states."""

from __future__ import annotations

import numpy as np
import pytest
from test_web_ros2 import Q0, RATE, domain, loopback, robot, robot_process, settings_for

from constraints.kinematics import frame_placement
from web.app import TeleopApp

__all__ = ["domain", "loopback", "robot", "robot_process"]  # the fixtures used here


def page(robot, domain: int, tmp_path) -> TeleopApp:
    """The page on the sim, its watchdog at 1 s (not under test here: a loaded machine
    pauses the sim beyond the default 50 ms now and then)."""
    return TeleopApp(robot, rate=RATE, plant="ros2",
                     ros2_settings=settings_for(domain, stale_after=1.0),
                     record_dir=tmp_path, scene_dir=tmp_path)


def tip(app: TeleopApp) -> np.ndarray:
    return app.robots.loops["main"].ee_placements()[0].translation.copy()


def test_a_scene_from_elsewhere_is_refused_and_one_from_here_moves_nothing(
        robot, domain, robot_process, tmp_path):
    """A scene saved at home (0.15 rad from the robot on one joint) is refused by name,
    nothing changed; one saved where the robot is opens with every target on the tool,
    and the robot stays within 0.1 mm over half a second."""
    app = page(robot, domain, tmp_path)
    try:
        start = tip(app)
        elsewhere = app.scenes.scene()
        elsewhere["q"]["main"] = [float(x) for x in robot.q_home]
        before = app.robots.loops["main"]
        with pytest.raises(ValueError, match="a real robot cannot jump there"):
            app.scenes.apply(elsewhere)
        assert app.robots.loops["main"] is before
        here = app.scenes.scene()
        here["target"]["position"] = [float(x) for x in start + [0.0, 0.05, 0.0]]
        app.scenes.apply(here)
        np.testing.assert_allclose(app.console.target.translation, tip(app), atol=1e-9)
        for _ in range(int(RATE / 2)):
            app.step()
        assert np.linalg.norm(tip(app) - start) < 1e-4
    finally:
        app.ros2.close()


def test_home_takes_the_robot_home_on_a_path_and_never_jumps(robot, domain, robot_process,
                                                             tmp_path):
    """Home with nothing placed: the targets start on the tool (no jump), the robot
    moves on the joint path at the speed caps (its tip over every 0.1 s at most 1.5 times
    the linear cap: the states arrive in bursts), and its tool gets home."""
    app = page(robot, domain, tmp_path)
    try:
        assert np.max(np.abs(app.robots.loops["main"].q - Q0)) < 1e-3  # it starts where it is
        start = tip(app)
        assert app.console.home() == ""
        np.testing.assert_allclose(app.console.target.translation, start, atol=1e-6)
        cap = app.robots.config.max_linear_speed
        window = int(RATE / 10)  # states arrive in bursts: the speed over 0.1 s
        previous = start
        for step in range(int(20 * RATE)):
            app.step()
            if step % window == window - 1:
                now = tip(app)
                assert np.linalg.norm(now - previous) <= 1.5 * cap * window / RATE
                previous = now
            if not app.homing.active:
                break
        assert not app.homing.active
        for _ in range(int(2 * RATE)):  # the robot's lag behind the path's last pose
            app.step()
        data = robot.model.createData()
        home = frame_placement(robot.model, robot.q_home, robot.ee_frame_ids[0], data)
        assert np.linalg.norm(tip(app) - home.translation) < 1e-3
    finally:
        app.ros2.close()
