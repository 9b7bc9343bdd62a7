"""From a device's motion to its EE's target (docs/design.md section 19.1), the feedback
wrench (19.3) and the watchdog (19.2), through the UI core's control tick."""

from __future__ import annotations

import math
import time

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, strategies as st

from constraints.collision import CollisionRows
from teleop import load_robot
from teleop.experiments.sessions import load_session
from teleop.inputs import (CLUTCH, DEFAULT_VIEW, FeedbackGains, FeedbackState, InputSample,
                           InputSource, feedback_wrench, followed_pose,
                           integrated_twist, view_rotation)
from web.app import TeleopApp

unit = st.floats(-1.0, 1.0, allow_nan=False)
small = st.floats(-0.05, 0.05, allow_nan=False)


def rotation_of(axis_angle) -> np.ndarray:
    return pin.exp3(np.asarray(axis_angle, dtype=float))


poses = st.tuples(st.tuples(small, small, small), st.tuples(unit, unit, unit)).map(
    lambda pa: pin.SE3(rotation_of(pa[1]), np.array(pa[0])))


@given(path=st.lists(poses, min_size=2, max_size=8), view=st.tuples(unit, unit, unit),
       scale=st.floats(0.05, 5.0), start=poses)
def test_incremental_mapping_equals_the_motion_since_the_first_sample(path, view, scale, start):
    """Sample by sample, the target ends where the anchored formula written here puts it:
    p0 + s R (p_n - p_0), R R_n R_0^T R^T R*_0."""
    rotation = rotation_of(view)
    target = start
    for previous, current in zip(path, path[1:]):
        target = followed_pose(target, previous, current, rotation, scale)
    expected_position = start.translation + scale * rotation @ (path[-1].translation
                                                                - path[0].translation)
    expected_rotation = rotation @ path[-1].rotation @ path[0].rotation.T @ rotation.T \
        @ start.rotation
    assert target.translation == pytest.approx(expected_position, abs=1e-12)
    assert target.rotation == pytest.approx(expected_rotation, abs=1e-9)


@given(device=poses, view=st.tuples(unit, unit, unit))
def test_absolute_orientation_is_the_devices_in_the_view(device, view):
    rotation = rotation_of(view)
    target = followed_pose(pin.SE3.Identity(), device, device, rotation, 1.0,
                           absolute_orientation=True)
    assert target.rotation == pytest.approx(rotation @ device.rotation, abs=1e-12)
    assert target.translation == pytest.approx(np.zeros(3), abs=0.0)


@given(twist=st.tuples(*[st.floats(-0.1, 0.1)] * 6), view=st.tuples(unit, unit, unit),
       scale=st.floats(0.1, 3.0), steps=st.integers(1, 50))
def test_a_held_rate_command_integrates_to_its_exponential(twist, view, scale, steps):
    rotation, dt = rotation_of(view), 1e-3
    target = start = pin.SE3(rotation_of((0.1, -0.2, 0.3)), np.array([0.4, 0.1, 0.9]))
    for _ in range(steps):
        target = integrated_twist(target, twist, rotation, scale, dt)
    v, w = np.array(twist[:3]), np.array(twist[3:])
    assert target.translation == pytest.approx(start.translation
                                               + scale * steps * dt * rotation @ v, abs=1e-12)
    assert target.rotation == pytest.approx(pin.exp3(steps * dt * rotation @ w)
                                            @ start.rotation, abs=1e-10)


def look_at_wxyz(position, target, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """An OpenCV camera (x right, y down, z forward) at ``position`` looking at
    ``target``: its wxyz, and the screen's right in the world, written independently."""
    forward = np.subtract(target, position, dtype=float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    quaternion = pin.Quaternion(np.column_stack([right, down, forward]))
    return np.array([quaternion.w, quaternion.x, quaternion.y, quaternion.z]), right


@given(azimuth=st.floats(-math.pi, math.pi), elevation=st.floats(-1.2, 1.2))
def test_the_devices_x_is_the_screens_right_and_its_y_the_screens_up(azimuth, elevation):
    position = 2.0 * np.array([math.cos(azimuth) * math.cos(elevation),
                               math.sin(azimuth) * math.cos(elevation), math.sin(elevation)])
    wxyz, right = look_at_wxyz(position, (0.0, 0.0, 0.0))
    rotation = view_rotation(wxyz)
    assert rotation[:, 0] == pytest.approx(right, abs=1e-9)
    assert rotation[:, 2] == pytest.approx(position / 2.0, abs=1e-9)  # towards the operator
    assert rotation[:, 1] @ np.array([0.0, 0.0, 1.0]) >= -1e-12  # up is not down
    assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_the_feedback_wrench_is_its_three_terms_bounded():
    ee = pin.SE3(rotation_of((0.0, 0.0, 0.02)), np.array([0.5, 0.0, 0.8]))
    target = pin.SE3(np.eye(3), np.array([0.5, 0.003, 0.8]))
    rows = CollisionRows(np.zeros((2, 7)), np.zeros(2), ("link_a | box", "link_b | box"),
                         np.array([0.01, 0.2]),
                         np.array([[[0.0, 0.0, 0.01], [0.0, 0.0, 0.0]],
                                   [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]]))
    gains = FeedbackGains()
    wrench = feedback_wrench(ee, target, [np.array([0.1, 0.0, 0.0])], rows, 0.05, DEFAULT_VIEW,
                             gains)
    # tracking 100 N/m x -3 mm along y, the port 0.1 N along x, the obstacle within
    # d_i = 5 cm: 200 N/m x 4 cm along +z; the far pair adds nothing
    force_world = np.array([0.1, -0.3, 8.0])
    force_world *= gains.max_force / np.linalg.norm(force_world)
    torque_world = gains.rotation_stiffness * np.array([0.0, 0.0, 0.02])
    assert wrench[:3] == pytest.approx(DEFAULT_VIEW.T @ force_world, abs=1e-12)
    assert wrench[3:] == pytest.approx(DEFAULT_VIEW.T @ torque_world, abs=1e-12)
    assert np.linalg.norm(wrench[:3]) == pytest.approx(gains.max_force)


@pytest.fixture
def app():
    return TeleopApp(load_robot("sda10f"), controller="cjm", rate=1000.0)


def pose_sample(position, sequence, buttons=0, arrival=None) -> InputSample:
    return InputSample("pose", (*position, 1.0, 0.0, 0.0, 0.0), buttons, sequence,
                       sequence * 1e-3 if arrival is None else arrival)


def test_a_pose_source_moves_its_target_through_the_clutch_and_a_new_scale_without_jumps(app):
    source = InputSource("test")
    app.devices.attach(source)
    start = app.console.targets[0].translation.copy()
    source.offer(pose_sample((0.3, 0.2, 0.1), 1))  # the first sample only anchors
    app.step()
    assert app.console.targets[0].translation == pytest.approx(start, abs=0.0)
    source.offer(pose_sample((0.31, 0.2, 0.1), 2))
    app.step()
    moved = start + DEFAULT_VIEW @ np.array([0.01, 0.0, 0.0])
    assert app.console.targets[0].translation == pytest.approx(moved, abs=1e-12)
    source.offer(pose_sample((0.33, 0.2, 0.1), 3, buttons=CLUTCH))  # the device's clutch
    app.step()
    assert app.console.targets[0].translation == pytest.approx(moved, abs=1e-12)
    assert app.devices[0].state == FeedbackState.CLUTCHED
    app.console.set_motion_scale(0.5)  # while the device is clutched: no jump on coupling
    source.offer(pose_sample((0.33, 0.2, 0.1), 4))
    app.step()
    assert app.console.targets[0].translation == pytest.approx(moved, abs=1e-12)
    source.offer(pose_sample((0.33, 0.22, 0.1), 5))
    app.step()
    assert app.console.targets[0].translation == pytest.approx(
        moved + 0.5 * DEFAULT_VIEW @ np.array([0.0, 0.02, 0.0]), abs=1e-12)
    assert source.counts["applied"] == 5 and source.latencies.count == 5


def test_a_twist_source_integrates_its_rate_command_each_period(app):
    source = InputSource("rate")
    source.watchdog = False
    app.devices.attach(source)
    start = app.console.targets[0].translation.copy()
    source.offer(InputSample("twist", (0.02, 0.0, -0.01, 0.0, 0.0, 0.0), 0, 1, 0.0))
    for _ in range(100):
        app.step()
    expected = start + 100 * 1e-3 * DEFAULT_VIEW @ np.array([0.02, 0.0, -0.01])
    assert app.console.targets[0].translation == pytest.approx(expected, abs=1e-12)
    app.console.set_clutch(True)  # the console's clutch stops it
    app.step()
    assert app.console.targets[0].translation == pytest.approx(expected, abs=1e-12)



def streaming_through_a_hole(acceleration_limits: bool, task_mode: str | None = None):
    """sda10f with a hole and a source streaming 3 cm/s along the device's x for 0.3 s:
    the app (in ``task_mode``, else its default) and the source."""
    app = TeleopApp(load_robot("sda10f"), controller="cjm", rate=1000.0,
                    acceleration_limits=acceleration_limits)
    if task_mode is not None:
        app.robots.set_task_mode(task_mode)
    app.constraints.add("hole", distance=0.08)
    source = InputSource("test")
    app.devices.attach(source)
    for k in range(1, 301):
        source.offer(pose_sample((3e-5 * k, 0.0, 0.0), k, arrival=time.perf_counter()))
        app.step()
    return app, source

@pytest.mark.parametrize("acceleration_limits", [False, True])
def test_the_watchdog_releases_a_silent_source_and_the_robot_stops_at_once(acceleration_limits):
    """A silent source: its target goes where the EE is and every loop's filtered target
    with it, so the next command is (nearly) zero although the robot was moving; with
    acceleration limits the robot brakes at them, still within the braking time of its
    fastest joint (docs/design.md 8.4)."""
    app, source = streaming_through_a_hole(acceleration_limits, "pose")  # no null space left
    moving = float(np.max(np.abs(app.robots.loops["main"].last_qd)))
    assert moving > 1e-2
    source.last_arrival = time.perf_counter() - 0.2  # silent for 200 ms
    app.step()
    assert app.devices[0].state == FeedbackState.HELD
    assert "silent for 200 ms" in app.devices[0].reason
    ee = app.robots.loops["main"].ee_placements()[0]
    if not acceleration_limits:
        app.step()
        assert np.max(np.abs(app.robots.loops["main"].last_qd)) < 1e-3
        assert app.console.targets[0].translation == pytest.approx(ee.translation, abs=1e-4)
    else:  # braked at the limits, past the held target by the braking distance, then back
        speeds = np.abs(app.robots.loops["main"].last_qd)
        braking = int(np.max(np.ceil(speeds / (app.robot.acceleration_limit * 1e-3)))) + 2
        for _ in range(braking):
            app.step()
        assert np.max(np.abs(app.robots.loops["main"].last_qd)) <= 0.2 * moving
        periods = 0
        while np.max(np.abs(app.robots.loops["main"].last_qd)) >= 1e-3 and periods < 500:
            app.step()
            periods += 1
        assert periods < 500  # at rest within 0.5 s
    # the next stream starts where the target is: its first sample only anchors
    held = app.console.targets[0].translation.copy()
    source.offer(pose_sample((5.0, 5.0, 5.0), 1, arrival=time.perf_counter()))
    app.step()
    assert app.console.targets[0].translation == pytest.approx(held, abs=0.0)
    assert app.devices[0].state == FeedbackState.FOLLOWING


def test_a_recording_gets_each_sources_counts_and_latencies(tmp_path):
    app = TeleopApp(load_robot("sda10f"), controller="cjm", rate=1000.0, record_dir=tmp_path)
    source = InputSource("test")
    app.devices.attach(source)
    path = app.start_recording("devices.jsonl")
    for k in range(1, 1501):
        source.offer(pose_sample((1e-5 * k, 0.0, 0.0), k, arrival=0.0))
        app.step()
    for _ in range(10):  # the last move is written within 10 periods
        app.step()
    app.stop_recording()
    session = load_session(path)
    lines = [event for event in session.events if event["type"] == "input"]
    assert [line["source"] for line in lines] == ["test", "test"]
    assert lines[0]["counts"]["applied"] >= 1 and lines[-1]["latency_ms"]["n"] >= 499
    assert all(line["latency_ms"]["p99"] >= line["latency_ms"]["p50"] > 0 for line in lines)
    targets = [event for event in session.events if event["type"] == "target"]
    assert 100 <= len(targets) <= 160  # at most one per 10 periods, not one per command
    assert targets[-1]["position"] == pytest.approx(app.console.targets[0].translation, abs=1e-12)


def test_a_second_source_on_the_same_ee_or_one_on_no_ee_is_refused(app):
    app.devices.attach(InputSource("first"))
    with pytest.raises(ValueError, match="already driven by first"):
        app.devices.attach(InputSource("second"))
    with pytest.raises(ValueError, match="no end effector 3"):
        app.devices.attach(InputSource("third", ee=3))
    with pytest.raises(ValueError, match="input timeout"):
        app.devices.set_input_timeout(0.0)


def test_a_gizmo_drag_after_a_release_moves_the_target_by_the_drag_only(app):
    """The watchdog puts the target on the EE; the gizmo's handle stays where it was, and
    a drag from there moves the target by the drag, not by the gap."""
    source = InputSource("test")
    app.devices.attach(source)
    for k in range(1, 41):  # the device takes the target 4 cm along its x
        source.offer(pose_sample((1e-3 * k, 0.0, 0.0), k, arrival=time.perf_counter()))
        app.step()
    source.last_arrival = time.perf_counter() - 1.0
    app.step()
    assert app.devices[0].state == FeedbackState.HELD
    before = app.console.targets[0].translation.copy()
    handle = app.console.gizmo.copy()  # where the page's handle still is
    app.console.move_gizmo(handle.translation + [0.0, 0.0, 1e-3], (1.0, 0.0, 0.0, 0.0))
    assert app.console.targets[0].translation - before == pytest.approx([0.0, 0.0, 1e-3], abs=1e-12)


def test_absolute_orientation_follows_only_once_the_device_agrees_with_the_tool(app):
    source = InputSource("test")
    app.devices.attach(source)
    app.devices.set_orientation_mode(True)
    target = app.console.targets[0].copy()
    turned = pin.exp3(np.array([0.0, 0.0, math.pi / 2])) @ DEFAULT_VIEW.T @ target.rotation
    quaternion = pin.Quaternion(turned)
    source.offer(InputSample("pose", (0.0, 0.0, 0.0, quaternion.w, quaternion.x, quaternion.y,
                                      quaternion.z), 0, 1, time.perf_counter()))
    app.step()
    assert app.devices[0].state == FeedbackState.CLUTCHED
    assert "align the device with the tool: 90 deg apart" in app.devices[0].reason
    assert app.console.targets[0].rotation == pytest.approx(target.rotation, abs=1e-12)
    aligned = pin.Quaternion(DEFAULT_VIEW.T @ target.rotation)  # the tool's, in the view
    for k, x in ((2, 0.0), (3, 0.01)):
        source.offer(InputSample("pose", (x, 0.0, 0.0, aligned.w, aligned.x, aligned.y,
                                          aligned.z), 0, k, time.perf_counter()))
        app.step()
    assert app.devices[0].state == FeedbackState.FOLLOWING
    assert app.console.targets[0].translation == pytest.approx(
        target.translation + DEFAULT_VIEW @ [0.01, 0.0, 0.0], abs=1e-9)
    app.devices.set_view((1.0, 0.0, 0.0, 0.0))  # another view: align again before moving
    source.offer(InputSample("pose", (0.02, 0.0, 0.0, aligned.w, aligned.x, aligned.y,
                                      aligned.z), 0, 4, time.perf_counter()))
    app.step()
    assert app.devices[0].state == FeedbackState.CLUTCHED
    assert app.console.targets[0].translation == pytest.approx(
        target.translation + DEFAULT_VIEW @ [0.01, 0.0, 0.0], abs=1e-9)


def test_a_rate_command_does_not_wind_the_target_up_ahead_of_the_robot(app):
    """Ten times the speed the robot may go: the target stays within the lead of the EE."""
    from web.app.devices import RATE_LEAD

    source = InputSource("rate")
    source.watchdog = False
    app.devices.attach(source)
    app.console.set_motion_scale(10.0)
    source.offer(InputSample("twist", (0.05, 0.0, 0.0, 0.0, 0.0, 0.0), 0, 1, 0.0))
    for _ in range(500):
        app.step()
        ee = app.robots.loops["main"].ee_placements()[0].translation
        assert np.linalg.norm(app.console.targets[0].translation - ee) <= RATE_LEAD + 0.5 * 1e-3
    assert source.counts["held_back"] > 100
    assert app.view.limitation().distance > 0.5 * RATE_LEAD  # it was pushing all along


def test_the_contact_force_at_the_tool_is_felt_scaled_and_bounded():
    """The sensor's force (tool frame) turned into the world by the tool's orientation,
    times the scale, at most ``max_contact_force`` alone, then in the device's frame."""
    ee = pin.SE3(rotation_of((0.3, -0.2, 0.5)), np.array([0.5, 0.0, 0.8]))
    gains = FeedbackGains(contact_scale=2.0, max_contact_force=3.0)
    small = np.array([0.0, 0.0, -0.5, 0.0, 0.0, 0.0])  # 0.5 N against the tool's z
    wrench = feedback_wrench(ee, ee, [], None, 0.05, DEFAULT_VIEW, gains, small)
    expected = 2.0 * 0.5 * -ee.rotation[:, 2]
    assert wrench[:3] == pytest.approx(DEFAULT_VIEW.T @ expected, abs=1e-12)
    large = np.array([4.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # 8 N scaled: bounded to 3 N
    wrench = feedback_wrench(ee, ee, [], None, 0.05, DEFAULT_VIEW, gains, large)
    assert wrench[:3] == pytest.approx(DEFAULT_VIEW.T @ (3.0 * ee.rotation[:, 0]), abs=1e-12)
    broken = np.full(6, np.nan)  # a broken reading renders nothing
    wrench = feedback_wrench(ee, ee, [], None, 0.05, DEFAULT_VIEW, gains, broken)
    assert np.all(wrench[:3] == 0.0) and np.all(np.abs(wrench[3:]) < 1e-12)


def test_with_position_and_roll_the_tip_stops_at_once_and_the_arm_settles_around_it():
    """The page's default with a port (position and roll, docs/design.md 20): when the
    watchdog holds a silent source, the tip stops at once (its linear velocity J_v qd, from
    Pinocchio, below 1 um/s) while the joints' null-space motion towards the posture goes on
    slowly (a few mrad/s), the port held."""
    app, source = streaming_through_a_hole(False)
    loop = app.robots.loops["main"]
    assert loop.task_modes != ("pose",)
    source.last_arrival = time.perf_counter() - 0.2  # silent for 200 ms
    app.step()
    app.step()
    model = app.robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, loop.q)
    jacobian = pin.getFrameJacobian(model, data, model.getFrameId(app.robot.ee_frame),
                                    pin.LOCAL_WORLD_ALIGNED)
    assert np.linalg.norm(jacobian[:3] @ loop.last_qd) < 1e-6
    assert 0.0 < np.max(np.abs(loop.last_qd)) < 1e-2  # settling in the null space, slowly
    hole = loop.constraints[0]
    pin.updateFramePlacements(model, data)
    assert hole.violation(data.oMf[loop.controller.constraint_frames[0]]) < 1e-6
