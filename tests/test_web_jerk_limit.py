"""``teleop web --jerk-limit`` (issue 32 item 2, docs/design.md 8.5): every loop of the page
keeps the limit on every joint. The jerk is measured from the commands the loop sent, in
the test, against the limit; the same drag without it exceeds it."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from web.app import TeleopApp
from web.cli import build_parser

LIMIT = 1000.0  # rad/s^3


def commanded_jerk(app: TeleopApp, seconds: float, offset: np.ndarray) -> float:
    """The largest |qd_k - 2 qd_k-1 + qd_k-2| / dt^2 over the main loop's commands while
    the target jumps by ``offset`` (a drag of the gizmo) with a hole in place."""
    app.constraints.add("hole", distance=0.08)
    target = app.console.target
    quaternion = pin.Quaternion(target.rotation)
    app.console.set_target(target.translation + offset,
                   [quaternion.w, quaternion.x, quaternion.y, quaternion.z])
    commands = []
    for _ in range(int(seconds * app.robots.config.rate)):
        app.step()
        commands.append(app.robots.loops["main"].last_qd.copy())
    second_differences = np.diff(np.array(commands), n=2, axis=0)
    return float(np.abs(second_differences).max()) / app.robots.config.dt**2


def test_every_command_of_the_page_keeps_the_jerk_limit(sda10f, tmp_path):
    offset = np.array([0.03, -0.02, 0.01])
    limited = TeleopApp(sda10f, record_dir=tmp_path, scene_dir=tmp_path / "scenes",
                        jerk_limit=LIMIT)
    free = TeleopApp(sda10f, record_dir=tmp_path, scene_dir=tmp_path / "scenes")
    assert commanded_jerk(limited, 0.6, offset) <= LIMIT * (1 + 1e-9)
    assert commanded_jerk(free, 0.6, offset) > 2 * LIMIT


def test_the_jerk_limit_reaches_the_ghost_and_a_switched_controller(sda10f, tmp_path):
    app = TeleopApp(sda10f, ghost="qp:daqp", record_dir=tmp_path,
                    scene_dir=tmp_path / "scenes", jerk_limit=LIMIT)
    for loop in app.robots.loops.values():
        np.testing.assert_array_equal(loop.controller.joint_bounds.jerk_limit, LIMIT)
    app.robots.set_controller("qp:proxqp")
    np.testing.assert_array_equal(app.robots.loops["main"].controller.joint_bounds.jerk_limit, LIMIT)


def test_a_jerk_limit_without_acceleration_limits_or_out_of_range_is_refused(sda10f, tmp_path):
    with pytest.raises(ValueError, match="jerk limit needs the acceleration limits"):
        TeleopApp(sda10f, record_dir=tmp_path, acceleration_limits=False, jerk_limit=LIMIT)
    with pytest.raises(ValueError, match="jerk_limit must be"):
        TeleopApp(sda10f, record_dir=tmp_path, jerk_limit=-1.0)
    assert build_parser().parse_args(["--jerk-limit", "5000"]).jerk_limit == 5000.0
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--jerk-limit", "0"])
