"""The browser session's logic without a browser: actions, errors, recording, threads."""

from __future__ import annotations

import json
import time
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from teleop.experiments.compare import run_plan
from teleop.experiments.sessions import load_session, session_plan
from web.app import ControlThread, TeleopApp


@pytest.fixture()
def app(sda10f, tmp_path):
    return TeleopApp(sda10f, controller="cjm", record_dir=tmp_path,
                     scene_dir=tmp_path / "scenes")


def ee_position(app, which="main"):
    loop = app.robots.loops[which]
    return loop.ee_placement().translation


def run(app, seconds):
    for _ in range(int(seconds * app.robots.config.rate)):
        app.step()


def nudge(app, offset):
    target = app.console.target
    quaternion = pin.Quaternion(target.rotation)
    app.console.set_target(target.translation + offset,
                           [quaternion.w, quaternion.x, quaternion.y, quaternion.z])


def test_target_moves_the_robot_and_the_hole_holds(app):
    hole_id = app.constraints.add("hole", distance=0.08)
    assert app.constraints.entries[hole_id].kind == "hole"
    start = ee_position(app)
    nudge(app, [0.01, 0.0, -0.005])
    run(app, 0.5)
    assert np.linalg.norm(ee_position(app) - (start + [0.01, 0.0, -0.005])) < 1e-4
    errors = np.array(app.robots.traces["main"].constraint_error)
    assert errors.size > 10 and errors.max() <= 1e-6


def test_side_by_side_robots_follow_the_same_target(app):
    app.constraints.add("hole", distance=0.08)
    app.robots.set_ghost("qp:daqp")
    nudge(app, [0.0, 0.01, 0.0])
    run(app, 0.3)
    np.testing.assert_allclose(ee_position(app, "ghost"), ee_position(app, "main"), atol=1e-6)
    snapshot = app.view.snapshot()
    assert set(snapshot["robots"]) == {"main", "ghost"}
    assert snapshot["robots"]["ghost"]["spec"] == "qp:daqp"
    app.robots.set_ghost(None)
    assert set(app.view.snapshot()["robots"]) == {"main"}


def test_switching_controller_keeps_the_state(app):
    app.constraints.add("hole", distance=0.08)
    nudge(app, [0.005, 0.0, 0.0])
    run(app, 0.1)
    q = app.robots.loops["main"].q.copy()
    app.robots.set_controller("qp:proxqp")
    assert app.robots.specs["main"] == "qp:proxqp"
    np.testing.assert_array_equal(app.robots.loops["main"].q, q)
    run(app, 0.2)
    assert app.robots.last_records["main"].constraint_error <= 1e-6
    with pytest.raises(ValueError, match="unknown controller"):
        app.robots.set_controller("pid")
    assert app.robots.specs["main"] == "qp:proxqp"


def test_a_moving_hole_is_followed(app):
    hole_id = app.constraints.add("hole", distance=0.08)
    center = app.constraints.entries[hole_id].position.copy()
    app.constraints.move(hole_id, center + [0.0, 0.0, 0.003])
    run(app, 0.5)
    assert np.linalg.norm(app.constraints.entries[hole_id].position - (center + [0, 0, 0.003])) < 1e-5
    assert app.robots.last_records["main"].constraint_error < 1e-5


@pytest.mark.parametrize("robot_name, move", [("sda10f", 0.05), ("sda10f", 0.20),
                                              ("ur5_instrument", 0.05)])
def test_a_hole_moved_far_glides_inside_the_joint_limits(robot_name, move, tmp_path):
    """A hole dragged 5 or 20 cm: speed-capped, no joint above its limits at any tick, the
    hole held on the way and within 1 um 2 s after it arrives."""
    from teleop import load_robot
    from teleop.loop.moving_geometry import MAX_GEOMETRY_SPEED

    robot = load_robot(robot_name)
    app = TeleopApp(robot, controller="cjm", record_dir=tmp_path)
    hole_id = app.constraints.add("hole", distance=0.08 if robot_name == "sda10f" else 0.2)
    goal = app.constraints.entries[hole_id].position + [0.0, move, 0.0]
    app.constraints.move(hole_id, goal)
    controller = app.robots.loops["main"].controller
    dt = app.robots.config.dt
    glide_ticks = int(move / MAX_GEOMETRY_SPEED / dt) + int(0.5 / dt)  # + the filter's tail
    previous = app.constraints.entries[hole_id].position
    for tick in range(glide_ticks + int(2.0 / dt)):
        app.step()
        qd = app.robots.loops["main"].last_qd
        assert np.all(np.abs(qd) <= controller.velocity_limit * (1 + 1e-9)), tick
        new_q = app.robots.loops["main"].q
        assert np.all(new_q <= robot.model.upperPositionLimit + 1e-12), tick
        assert np.all(new_q >= robot.model.lowerPositionLimit - 1e-12), tick
        position = app.constraints.entries[hole_id].position
        assert np.linalg.norm(position - previous) <= MAX_GEOMETRY_SPEED * dt * (1 + 1e-9)
        previous = position
    np.testing.assert_allclose(app.constraints.entries[hole_id].position, goal, atol=1e-9)
    record = app.robots.last_records["main"]
    print(f"{robot_name} hole moved {move} m: error {record.constraint_error:.2e} m, "
          f"status {record.status}, EE error {record.ee_position_error:.3g} m")
    assert record.constraint_error < 1e-6


def test_a_rate_too_low_for_the_gain_is_refused_and_nothing_changes(app):
    app.constraints.add("hole", distance=0.08)
    app.robots.set_gain(500.0)
    with pytest.raises(ValueError, match=r"unstable at 50 Hz \(K dt = 10"):
        app.robots.set_rate(50.0)
    assert app.robots.config.rate == 1000.0
    assert all(loop.controller.dt == 1e-3 for loop in app.robots.loops.values())
    app.robots.set_gain(80.0)
    app.robots.set_rate(50.0)  # K dt = 1.6 < 2: fine
    assert all(loop.controller.dt == 0.02 for loop in app.robots.loops.values())
    run(app, 0.1)
    assert app.robots.last_records["main"].constraint_error < 1e-6


def test_planes_and_barriers_and_removal(app):
    # any non-zero normal, normalised
    plane_id = app.constraints.add("plane", distance=0.08, normal=[0.0, 2.0, 0.0])
    barrier_id = app.constraints.add("barrier", distance=0.05, normal=[0.0, 0.0, 1.0], offset=0.01)
    assert app.constraints.entries[plane_id].constraint.normal.tolist() == [0.0, 1.0, 0.0]
    assert app.constraints.entries[barrier_id].kind == "barrier"
    run(app, 0.05)
    kinds = {e["kind"] for e in app.view.snapshot()["constraints"]}
    assert kinds == {"plane", "barrier"}
    app.constraints.remove(plane_id)
    assert list(app.constraints.entries) == [barrier_id]
    with pytest.raises(ValueError, match="no constraint 'plane-1'"):
        app.constraints.remove(plane_id)


@pytest.mark.parametrize("action, message", [
    (lambda app: app.constraints.add("plane", distance=0.08, normal=[0.0, 0.0, 0.0]), "non-zero"),
    (lambda app: app.constraints.add("barrier", distance=0.08, normal=[0.0, 0.0, 1.0],
                                    offset=-0.05), "wrong side"),
    (lambda app: app.console.set_target([np.nan, 0, 0], [1, 0, 0, 0]), "finite"),
    (lambda app: app.robots.set_rate(10.0), "between 50 and 5000"),
    (lambda app: app.robots.set_gain(5000.0), "gain must be in"),
    (lambda app: app.constraints.add("hole", distance=1e6), "hole distance must be between 0 and"),
    (lambda app: app.constraints.add("hole", distance=-19.0), "hole distance must be between 0 and"),
    (lambda app: app.constraints.add("hole", distance=None), "hole distance must be a number"),
    (lambda app: app.robots.set_damping(-1.0), "damping must be"),
    (lambda app: app.constraints.move("hole-9", [0, 0, 0]), "no constraint"),
    (lambda app: app.stop_recording(), "not recording"),
])
def test_impossible_actions_raise_a_message_for_the_operator(app, action, message):
    with pytest.raises(ValueError, match=message):
        action(app)
    run(app, 0.01)  # and the app keeps running
    assert np.isfinite(app.robots.loops["main"].q).all()


def test_home_keeps_the_constraints_and_clear_removes_them(app):
    hole_id = app.constraints.add("hole", distance=0.08)
    nudge(app, [0.01, 0.0, 0.0])
    run(app, 0.2)
    start = ee_position(app).copy()
    # with a constraint: a joint path home that keeps it, its EE poses followed in full pose
    assert app.console.home() == ""
    assert list(app.constraints.entries) == [hole_id] and app.homing.active
    assert app.robots.loops["main"].task_modes == ("pose",)
    assert app.view.limitation().words.startswith("going home through the constraints")
    np.testing.assert_allclose(app.console.target.translation, start, atol=1e-12)  # from where it is
    np.testing.assert_allclose(app.console.gizmo.translation, start, atol=1e-12)
    home = app.robots.loops["main"].ee_placement(app.robot.q_home)
    run(app, app.homing.run.times[-1] + 0.6)
    assert not app.homing.active and app.robots.loops["main"].task_modes == ("position_roll",)
    np.testing.assert_allclose(app.console.target.translation, home.translation, atol=1e-9)
    assert np.linalg.norm(ee_position(app) - home.translation) < 1e-4
    assert np.max(np.abs(app.robots.loops["main"].q - app.robot.q_home)) < 1e-3
    assert max(app.robots.traces["main"].constraint_error) < 1e-6  # held on the way
    assert app.constraints.clear() == 1 and not app.constraints.entries
    nudge(app, [0.01, 0.0, 0.0])
    run(app, 0.1)
    app.console.home()  # without constraints: a reset, at once
    np.testing.assert_array_equal(app.robots.loops["main"].q, app.robot.q_home)
    np.testing.assert_allclose(app.console.target.translation, ee_position(app))


def test_recording_writes_a_session_that_replay_accepts(app, tmp_path):
    # the full pose: with a hole the default (position and roll) leaves two joint
    # directions to the posture, which the app (acceleration limits) and the replay below
    # (none) spend differently: the plane would be added 39 um off the replay's link
    app.robots.set_task_mode("pose")
    app.constraints.add("hole", distance=0.08)
    path = app.start_recording()
    assert path.parent == tmp_path
    nudge(app, [0.005, 0.0, 0.0])
    run(app, 0.2)
    plane_id = app.constraints.add("plane", distance=0.04, normal=[1.0, 0.0, 0.0])
    run(app, 0.1)
    app.constraints.remove(plane_id)
    run(app, 0.1)
    assert app.stop_recording() == path
    session = load_session(path)
    kinds = [e["type"] for e in session.events]
    assert kinds.count("add") == 2 and kinds.count("remove") == 1 and kinds[-1] == "end"
    assert session.duration == pytest.approx(0.4, abs=2e-3)
    # the plane added while the arm moves: held at once without acceleration limits; with
    # them (the default) the joints need a few periods to turn (23 um measured)
    result = run_plan(session_plan(session), "cjm", acceleration_limits=False)
    metrics = result.metrics()
    assert metrics["failed_steps"] == 0
    assert metrics["constraint_error_max_m"] < 1e-5
    limited = run_plan(session_plan(session), "cjm")
    assert limited.metrics()["failed_steps"] == 0
    assert limited.metrics()["constraint_error_max_m"] < 1e-4


def test_control_thread_runs_and_reports_its_rate(app):
    control = ControlThread(app)
    control.start()
    try:
        time.sleep(1.5)
        assert control.alive and control.error is None
        assert control.achieved_rate > 0
        assert app.ticker.ticks > 100
    finally:
        control.stop()
    assert not control.alive


# -- plots: one time base, the ghost's history, readable units ------------------------------


def test_plot_history_is_finite_and_the_ghost_turned_on_later_fills_its_own(app):
    from web.ui import PLOTS, plot_series

    app.constraints.add("hole", distance=0.08)
    nudge(app, [0.005, 0.0, 0.0])
    run(app, 0.5)
    snapshot = app.view.snapshot()
    for spec in PLOTS:
        t, series = plot_series(snapshot, spec)
        if spec.ghost_only:
            assert series == {}  # no ghost: no deviation plot
            continue
        assert t.size == 25 and list(series) == ["main"]  # 0.5 s at 50 Hz
        assert np.isfinite(t).all() and np.isfinite(series["main"]).all()
    app.robots.set_ghost("qp:daqp")  # as the checkbox does, 0.5 s into the session
    assert app.robots.loops["ghost"].t == app.now
    nudge(app, [0.0, 0.005, 0.0])
    run(app, 0.3)
    snapshot = app.view.snapshot()
    main, ghost = snapshot["robots"]["main"]["trace"], snapshot["robots"]["ghost"]["trace"]
    assert ghost["t"].size == 15  # its own samples since it joined, at the main's times
    np.testing.assert_array_equal(ghost["t"], main["t"][-15:])
    for spec in PLOTS:
        t, series = plot_series(snapshot, spec)
        assert t.size == 15 and all(s.size == 15 and np.isfinite(s).all() for s in series.values())
        assert list(series) == (["ghost"] if spec.ghost_only else ["main", "ghost"])
    # the two controllers differ a little while they move: the deviation plot says how much
    t, series = plot_series(snapshot, PLOTS[-1])
    assert 0.0 < series["ghost"].max() < 1.0, series["ghost"]


@pytest.mark.parametrize("values, quantity, unit", [
    ([0.0, 2e-7, 5e-8], "m", "nm"),  # 200 nm, not "0, 0, 0" m
    ([0.0, 3e-5], "m", "µm"),
    ([0.012, 0.004], "m", "mm"),
    ([0.0, 0.0], "m", "nm"),  # an all-zero trace: 0 ... 1 nm
    ([25.0, 90.0], "us", "µs"),
    ([0.0, 4e-4], "rad/s", "µrad/s"),
])
def test_plot_units_make_small_values_readable(values, quantity, unit):
    from web.ui import display_unit

    name, size = display_unit(np.array(values), quantity)
    assert name == unit
    peak = max(values) / size
    assert peak == 0.0 or 1.0 <= peak < 1000.0
    # hysteresis: a peak that drifts a little below the unit keeps it
    assert display_unit(np.array(values) * 0.8, quantity, current=name)[0] == name


# -- side by side ---------------------------------------------------------------------------


def test_ghost_offset_is_beside_the_robot_and_checked(app):
    offset = app.robots.ghost_offset
    assert abs(offset[2]) < 1e-12 and 0.5 < np.linalg.norm(offset) < 2.0  # beside, on the floor
    app.robots.set_ghost_offset([0.0, 0.0, 0.0])  # overlay
    np.testing.assert_array_equal(app.robots.ghost_offset, np.zeros(3))
    for bad, message in (([0.0, 9.0, 0.0], "at most 5 m"), ([np.nan, 0, 0], "finite"),
                         ([1.0, 2.0], "shape")):
        with pytest.raises(ValueError, match=message):
            app.robots.set_ghost_offset(bad)
    np.testing.assert_array_equal(app.robots.ghost_offset, np.zeros(3))


# -- the operator's console: clutch, motion scaling, nudges ----------------------------------


def move_gizmo_by(app, displacement):
    gizmo = app.console.gizmo
    quaternion = pin.Quaternion(gizmo.rotation)
    app.console.move_gizmo(gizmo.translation + displacement,
                   [quaternion.w, quaternion.x, quaternion.y, quaternion.z])


def test_motion_scaling_moves_the_target_by_scale_times_the_gizmo(app):
    start = app.console.target.translation.copy()
    app.console.set_motion_scale(0.2)
    move_gizmo_by(app, [0.10, 0.0, 0.0])  # a 10 cm gizmo move ...
    np.testing.assert_allclose(app.console.target.translation - start, [0.02, 0.0, 0.0], atol=1e-12)
    move_gizmo_by(app, [0.0, -0.05, 0.0])  # ... displacement since the last clutch, scaled
    np.testing.assert_allclose(app.console.target.translation - start, [0.02, -0.01, 0.0], atol=1e-12)
    app.console.set_motion_scale(1.0)  # a new scale does not move the target
    np.testing.assert_allclose(app.console.target.translation - start, [0.02, -0.01, 0.0], atol=1e-12)
    move_gizmo_by(app, [0.0, 0.0, 0.01])
    np.testing.assert_allclose(app.console.target.translation - start, [0.02, -0.01, 0.01], atol=1e-12)
    for bad in (0.0, -1.0, 11.0, np.nan, None):
        with pytest.raises(ValueError, match="motion scale"):
            app.console.set_motion_scale(bad)


def test_clutch_decouples_the_gizmo_and_release_does_not_jump(app):
    start = app.console.target.copy()
    app.console.set_clutch(True)
    move_gizmo_by(app, [0.05, 0.03, -0.02])  # repositioning the hand, the target holds
    assert app.console.target.isApprox(start)
    run(app, 0.2)
    np.testing.assert_allclose(ee_position(app), start.translation, atol=1e-9)
    app.console.set_clutch(False)
    assert app.console.target.isApprox(start)  # no jump on release
    move_gizmo_by(app, [0.0, 0.0, 0.01])  # then it continues from where it was
    np.testing.assert_allclose(app.console.target.translation, start.translation + [0, 0, 0.01], atol=1e-12)
    # the gizmo's own rotation since the release turns the target by as much
    app.console.set_clutch(True)
    app.console.set_clutch(False)
    turn = pin.exp3(np.array([0.0, 0.0, 0.3]))
    gizmo = app.console.gizmo
    quaternion = pin.Quaternion(turn @ gizmo.rotation)
    app.console.move_gizmo(gizmo.translation, [quaternion.w, quaternion.x, quaternion.y, quaternion.z])
    before = start.rotation
    np.testing.assert_allclose(app.console.target.rotation, turn @ before, atol=1e-9)
    with pytest.raises(ValueError, match="engaged"):
        app.console.set_clutch("yes")


def test_nudges_and_gizmo_to_target(app):
    start = app.console.target.translation.copy()
    app.console.nudge_target([0.0, 0.0, 0.005])
    np.testing.assert_allclose(app.console.target.translation, start + [0, 0, 0.005], atol=1e-12)
    np.testing.assert_allclose(app.console.gizmo.translation, start, atol=1e-12)  # the gizmo stays
    run(app, 0.5)
    np.testing.assert_allclose(ee_position(app), app.console.target.translation, atol=1e-4)
    with pytest.raises(ValueError, match="at most 0.1 m"):
        app.console.nudge_target([0.0, 0.2, 0.0])
    pose = app.console.gizmo_to_target()
    np.testing.assert_allclose(pose.translation, app.console.target.translation)
    move_gizmo_by(app, [0.01, 0.0, 0.0])
    np.testing.assert_allclose(app.console.target.translation, start + [0.01, 0, 0.005], atol=1e-12)


# -- what limits the robot, in words ------------------------------------------------------------


def test_an_unreachable_target_is_said_in_words(app):
    app.robots.set_task_mode("pose")  # position and roll reach this target (the default with a hole)
    app.constraints.add("hole", distance=0.08)
    assert app.view.limitation().words == "on target" and app.view.limitation().status == "ok"
    nudge(app, [0.5, 0.0, 0.0])  # half a metre ahead, through a hole: not reachable
    run(app, 0.2)
    moving = app.view.limitation()
    assert moving.distance > 0.4 and "moving to the target" in moving.words or \
        "at its limit" in moving.words
    run(app, 8.0)
    stuck = app.view.limitation()
    print(f"unreachable target: {stuck.status}: {stuck.words} ({1e3 * stuck.distance:.1f} mm)")
    assert stuck.distance > 0.05
    assert "target out of reach" in stuck.details
    # what part is short, why, and what helps (docs/design.md 20.4)
    assert stuck.words.startswith(f"position {1e3 * stuck.distance:.1f} mm")
    assert "hole-1 takes two of the arm's freedoms" in stuck.words
    assert stuck.words.endswith("set the task mode to position and roll about the tool axis "
                                "(what a port allows)")
    assert stuck.status in ("least_squares", "scaled", "ok")
    assert app.robots.last_records["main"].constraint_error < 1e-6  # the hole held all along


def test_a_joint_at_its_limit_is_named():
    from controllers import SolveInfo, StepStatus
    from web.app import describe_limitation

    info = SolveInfo(status=StepStatus.LEAST_SQUARES, saturated_joints=(4,),
                     message="joint arm_joint_4_u at a limit; near a singularity (sigma_min "
                             "0.00074, damping 0.05): task not fully achievable")
    names = ["j0", "j1", "j2", "j3", "arm_joint_4_u"]
    stalled = SimpleNamespace(commanded_linear_velocities=np.array([[0.05, 0.0, 0.0]]),
                              actual_linear_velocities=np.array([[0.004, 0.003, 0.0]]))
    words = describe_limitation(info, stalled, 0.02, names)
    assert words.status == "least_squares"
    # the CJM's message names the joint and the damping: both reach the operator
    assert words.words == ("target out of reach; closest motion: joint arm_joint_4_u at a "
                           "limit; near a singularity (sigma_min 0.00074, damping 0.05): task "
                           "not fully achievable")
    scaled = SolveInfo(status=StepStatus.SCALED, saturated_joints=(4,), scale=0.5)
    following = SimpleNamespace(commanded_linear_velocities=np.array([[0.05, 0.0, 0.0]]),
                                actual_linear_velocities=np.array([[0.045, 0.01, 0.0]]))
    assert describe_limitation(scaled, following, 0.02, names).words == \
        "joint arm_joint_4_u at its limit; slowed to 50 % by the joint limits"
    degraded = describe_limitation(SolveInfo(status=StepStatus.CONSTRAINT_DEGRADED,
                                             message="residual 1e-6 m/s"), None, 0.0, names)
    assert degraded.words == "constraint degraded: residual 1e-6 m/s"
    scaled = describe_limitation(SolveInfo(status=StepStatus.SCALED, scale=0.25), None, 0.0, names)
    assert scaled.words == "slowed to 25 % by the joint limits"


def test_active_barriers_are_listed(app):
    barrier_id = app.constraints.add("barrier", distance=0.05, normal=[0.0, 0.0, 1.0], offset=0.002)
    assert app.view.active_inequalities() == []
    nudge(app, [0.0, 0.0, -0.05])  # down, into the barrier
    run(app, 1.0)
    assert app.view.active_inequalities() == [barrier_id]
    assert app.robots.last_records["main"].barrier_penetration < 1e-6
    geometry = app.view.snapshot()["constraints"][0]["geometry"]
    assert np.linalg.norm(geometry.error) < 1e-9  # held on the plane: no error to draw


def test_a_satisfied_barrier_has_no_error_to_draw(app):
    app.constraints.add("barrier", distance=0.05, normal=[0.0, 0.0, 1.0], offset=0.01)
    run(app, 0.05)
    (entry,) = app.view.snapshot()["constraints"]
    assert entry["kind"] == "barrier" and np.linalg.norm(entry["geometry"].error) == 0.0
    assert app.robots.last_records["main"].barrier_penetration == 0.0


def test_a_robot_without_a_constrained_link_says_how_to_get_one(tmp_path):
    from teleop import load_robot

    robot = load_robot(str(load_robot("sda10f").urdf_path))  # a URDF path: no constrained link
    app = TeleopApp(robot, record_dir=tmp_path)
    with pytest.raises(ValueError, match="no constrained link: start `teleop web` with "
                                         "--constrained-link"):
        app.constraints.add("hole", distance=0.08)


# -- scenes ---------------------------------------------------------------------------------


def test_a_scene_saved_and_loaded_restores_constraints_and_settings(sda10f, tmp_path):
    # the moved hole is corrected within 0.3 s without acceleration limits; with them its
    # drift feedback overshoots (docs/design.md 8.4)
    app = TeleopApp(sda10f, controller="cjm", record_dir=tmp_path, scene_dir=tmp_path / "scenes",
                    acceleration_limits=False)
    hole_id = app.constraints.add("hole", distance=0.08)
    barrier_id = app.constraints.add("barrier", distance=0.04, normal=[0.0, 0.0, 1.0], offset=0.01)
    app.robots.set_ghost("qp:daqp")
    app.robots.set_ghost_offset([0.0, -0.7, 0.0])
    app.robots.set_gain(80.0)
    app.robots.set_damping(0.01)
    app.robots.set_rate(500.0)
    app.console.set_motion_scale(0.2)
    nudge(app, [0.005, 0.0, 0.0])
    run(app, 0.3)
    app.constraints.move(hole_id, app.constraints.entries[hole_id].goal + [0.0, 0.0, 0.002])
    saved = app.scenes.save("a.json")
    assert saved == tmp_path / "scenes" / "a.json"
    scene = json.loads(saved.read_text())
    assert scene["format"] == "cjm-teleop-scene" and scene["robot"]["source"] == "sda10f"
    assert [c["id"] for c in scene["constraints"]] == [hole_id, barrier_id]
    q_saved = app.robots.loops["main"].q.copy()
    goals = {i: e.goal.copy() for i, e in app.constraints.entries.items()}
    target = app.console.target.copy()

    # change everything, then load
    app.constraints.clear()
    app.robots.set_ghost(None)
    app.robots.set_rate(1000.0)
    app.robots.set_gain(100.0)
    app.console.set_motion_scale(1.0)
    app.console.home()
    run(app, 0.1)
    app.scenes.load("a.json")
    assert list(app.constraints.entries) == [hole_id, barrier_id]
    assert [e.kind for e in app.constraints.entries.values()] == ["hole", "barrier"]
    for entry_id, goal in goals.items():
        np.testing.assert_allclose(app.constraints.entries[entry_id].goal, goal, atol=1e-12)
    assert app.robots.specs == {"main": "cjm", "ghost": "qp:daqp"}
    assert (app.robots.gain, app.robots.damping, app.robots.config.rate,
            app.console.motion_scale) == (80.0, 0.01, 500.0, 0.2)
    np.testing.assert_allclose(app.robots.ghost_offset, [0.0, -0.7, 0.0])
    np.testing.assert_allclose(app.robots.loops["main"].q, q_saved, atol=1e-12)
    assert app.console.target.isApprox(target, 1e-9)
    assert all(e.constraint.gain == 80.0 for e in app.constraints.entries.values())
    assert app.constraints.add("hole", distance=0.1) == "hole-3"  # new ids after the loaded ones
    run(app, 0.3)
    assert app.robots.last_records["main"].constraint_error < 1e-6


@pytest.mark.parametrize("change, message", [
    (lambda s: s.update(format="x"), "not a scene file"),
    (lambda s: s["robot"].update(source="ur5_instrument"), "this scene is for robot 'ur5_instrument'"),
    (lambda s: s["controllers"].update(main="pid"), "unknown controller 'pid'"),
    (lambda s: s.update(rate=10.0), "between 50 and 5000 Hz"),
    (lambda s: s["q"].update(main=[0.0] * 3), "q.main must have shape"),
    (lambda s: s["q"].update(main=[9.0] * 8), "outside the joint limits"),
    (lambda s: s["constraints"].append({"id": "x-1", "constraint": {"kind": "trocar"}}),
     r"constraints\[1\]: unknown constraint kind"),
    (lambda s: s.update(gain=5000.0), "unstable at 1000 Hz"),
    (lambda s: s.update(task_mode="roll"), "unknown task mode 'roll'"),
])
def test_a_bad_scene_is_refused_and_changes_nothing(app, change, message):
    app.constraints.add("hole", distance=0.08)
    scene = app.scenes.scene()
    change(scene)
    app.constraints.clear()
    app.robots.set_gain(50.0)
    with pytest.raises(ValueError, match=message):
        app.scenes.apply(scene)
    assert not app.constraints.entries and app.robots.gain == 50.0 and app.robots.specs == {"main": "cjm"}
    run(app, 0.01)


def test_scene_files_that_cannot_be_read(app, tmp_path):
    with pytest.raises(ValueError, match="no scene 'none.json' in the scene folder"):
        app.scenes.load("none.json")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "bad.json").write_text("{nope")
    with pytest.raises(ValueError, match="not JSON"):
        app.scenes.load("bad.json")
    (scenes / "dir.json").mkdir()
    with pytest.raises(ValueError, match="'dir.json' in the scene folder is not a file"):
        app.scenes.save("dir.json")


# -- the light tick ---------------------------------------------------------------------------


def test_measures_are_taken_at_the_history_rate_only(app, monkeypatch):
    app.constraints.add("hole", distance=0.08)
    app.robots.set_ghost("qp:daqp")
    measured = []
    for loop in app.robots.loops.values():
        original = loop.measure
        monkeypatch.setattr(loop, "measure", lambda step, f=original: measured.append(1) or f(step))
    nudge(app, [0.002, 0.0, 0.0])
    run(app, 1.0)  # 1000 ticks, 2 robots
    assert len(measured) == 2 * 50
    qd = app.robots.loops["main"].last_qd
    assert np.all(np.isfinite(qd)) and np.any(qd != 0.0)  # every tick commands the robot
    # what a light tick costs beyond the controllers (printed; the status shows it live)
    app.robots.set_ghost(None)
    costs = []
    for _ in range(2000):
        start = time.perf_counter()
        solve_us = app.step()
        costs.append(1e6 * (time.perf_counter() - start) - solve_us)
    print(f"\ntick beyond the controller: median {np.median(costs):.1f} us, "
          f"p90 {np.percentile(costs, 90):.1f} us")
    assert np.isfinite(costs).all()


def test_control_thread_reports_lateness_percentiles(app):
    """The timing the control thread reports once it has ticked 500 times and measured its
    first one-second window: waited for, up to 60 s (a fixed sleep of 1.5 s ended before
    the first window on a loaded machine)."""
    control = ControlThread(app)
    control.start()
    try:
        deadline = time.perf_counter() + 60.0
        while True:
            timing = control.timing()
            if timing.ticks > 500 and timing.achieved_rate > 0.0:
                break
            assert time.perf_counter() < deadline, f"no measured window in 60 s: {timing}"
            time.sleep(0.05)
    finally:
        control.stop()
    print(f"\n{timing}")
    assert timing.achieved_rate > 100
    assert 0.0 <= timing.lateness_p50_ms <= timing.lateness_p99_ms < 1e3
    assert 0.0 < timing.tick_p50_us <= timing.tick_p99_us
