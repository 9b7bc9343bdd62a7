"""The browser session's core with several end effectors (docs/design.md section 11): the
SDA10F's two arms, a trocar on each, and the same robot on a mobile base kept off a wall.

Everything here is measured from Pinocchio's forward kinematics of the robot's own
configuration, never from the app's report of it.
"""

from __future__ import annotations

import asyncio
import inspect
import json
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from teleop import load_robot
from web.app import TeleopApp
from web.scene import parse_scene, robot_from_dict, robot_to_dict, same_robot

HOLE_TOLERANCE = 1e-6  # m


@pytest.fixture()
def app(dual, tmp_path):
    return TeleopApp(dual, controller="cjm", record_dir=tmp_path / "sessions",
                     scene_dir=tmp_path / "scenes")


def ee_positions(app, which="main") -> np.ndarray:
    """Each EE's world position, by forward kinematics of the robot's q."""
    robot = app.robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, app.robots.loops[which].q)
    return np.array([data.oMf[frame].translation for frame in robot.ee_frame_ids])


def wxyz(pose: pin.SE3) -> list[float]:
    quaternion = pin.Quaternion(pose.rotation)
    return [quaternion.w, quaternion.x, quaternion.y, quaternion.z]


def drag(app, ee: int, displacement, steps: int, ticks_per_step: int, check=None) -> None:
    """Move EE ``ee``'s gizmo by ``displacement`` in ``steps`` equal moves, the control
    loop ticking ``ticks_per_step`` times after each (``check()`` after every tick)."""
    for _ in range(steps):
        gizmo = app.console.inputs[ee].gizmo
        app.console.move_gizmo(gizmo.translation + np.asarray(displacement) / steps, wxyz(gizmo), ee)
        for _ in range(ticks_per_step):
            app.step()
            if check is not None:
                check()


def run(app, seconds: float) -> None:
    for _ in range(int(round(seconds * app.robots.config.rate))):
        app.step()


def test_each_gizmo_moves_its_own_ee_only(app):
    """Without constraints the 15 joints meet both 6-entry tasks: the dragged EE reaches its
    target, the other does not move."""
    for ee, displacement in ((0, [0.02, -0.01, 0.015]), (1, [-0.015, -0.02, 0.01])):
        start = ee_positions(app)
        other = 1 - ee
        other_target = app.console.inputs[other].target.copy()
        drag(app, ee, displacement, steps=20, ticks_per_step=20)
        run(app, 0.5)
        end = ee_positions(app)
        np.testing.assert_allclose(app.console.inputs[ee].target.translation,
                                   start[ee] + displacement, atol=1e-6)
        assert np.linalg.norm(end[ee] - (start[ee] + displacement)) < 1e-4
        assert np.linalg.norm(end[other] - start[other]) < 1e-6, "the other EE moved"
        assert app.console.inputs[other].target.isApprox(other_target, 1e-12)
        limitations = app.view.snapshot()["robots"]["main"]["limitations"]
        assert [each.status for each in limitations] == ["ok", "ok"]
        assert all(each.distance < 1e-4 for each in limitations)


def test_holes_on_both_arms_hold_while_both_gizmos_move(app, dual):
    """A hole on each arm's link 6, each on that link's own axis, held to 1 um over 2240
    ticks of both gizmos moving; no joint past a position or velocity limit at any tick."""
    q = app.robots.loops["main"].q.copy()
    data = dual.model.createData()
    pin.framesForwardKinematics(dual.model, data, q)
    ids = [app.constraints.add("hole", distance=0.08, link=link) for link in dual.constrained_links]
    for hole_id, link in zip(ids, dual.constrained_links):
        hole = app.constraints.entries[hole_id].constraint
        assert hole.link == link
        expected = data.oMf[dual.model.getFrameId(link)].act(0.08 * dual.link_axes[link])
        np.testing.assert_allclose(hole.position, expected, atol=1e-12)  # on that arm's axis
    model = dual.model
    controller = app.robots.loops["main"].controller
    worst = {"hole": 0.0, "velocity": 0.0}

    def check() -> None:
        loop = app.robots.loops["main"]
        assert np.all(loop.q <= model.upperPositionLimit + 1e-12)
        assert np.all(loop.q >= model.lowerPositionLimit - 1e-12)
        assert np.all(np.abs(loop.last_qd) <= controller.velocity_limit * (1 + 1e-9))
        data_now = model.createData()
        pin.framesForwardKinematics(model, data_now, loop.q)
        for hole_id in ids:  # measured here, each hole against its own link
            hole = app.constraints.entries[hole_id].constraint
            error = hole.violation(data_now.oMf[model.getFrameId(hole.link)])
            worst["hole"] = max(worst["hole"], error)

    start = ee_positions(app)
    drag(app, 0, [0.0, 0.01, 0.01], steps=28, ticks_per_step=40, check=check)
    drag(app, 1, [0.01, 0.0, -0.01], steps=28, ticks_per_step=40, check=check)
    end = ee_positions(app)
    print(f"\ntwo holes, both gizmos dragged 14 mm: worst hole error {worst['hole']:.2e} m; "
          f"left EE moved {1e3 * np.linalg.norm(end[0] - start[0]):.1f} mm, right "
          f"{1e3 * np.linalg.norm(end[1] - start[1]):.1f} mm; status "
          f"{app.robots.last_records['main'].status}")
    assert worst["hole"] <= HOLE_TOLERANCE
    # each EE went the way its own gizmo did (11 joints left for 12 task entries: the
    # least-squares command, section 11.2, so not all the way)
    assert (end[0] - start[0]) @ [0.0, 0.01, 0.01] > 0.5 * 2e-4
    assert (end[1] - start[1]) @ [0.01, 0.0, -0.01] > 0.5 * 2e-4


def test_a_hole_or_lock_goes_on_the_chosen_arm_and_is_checked_against_that_arm(app, dual):
    right = dual.constrained_links[1]
    data = dual.model.createData()
    pin.framesForwardKinematics(dual.model, data, dual.q_home)
    link = data.oMf[dual.model.getFrameId(right)]
    reach = np.linalg.norm(link.actInv(data.oMf[dual.model.getFrameId(dual.ee_frames[1])].translation))
    with pytest.raises(ValueError, match=f"hole distance must be between 0 and {reach:.3f} m "
                                         f"\\(from the joint of {right} to the tool tip\\)"):
        app.constraints.add("hole", distance=reach + 0.01, link=right)
    with pytest.raises(ValueError, match="a hole goes on a constrained link: one of"):
        app.constraints.add("hole", distance=0.05, link="torso_link_b1")
    lock_id = app.constraints.add("point_lock", distance=0.05, link=right)
    lock = app.constraints.entries[lock_id].constraint
    assert lock.link == right
    np.testing.assert_allclose(lock.position, link.act(0.05 * dual.link_axes[right]), atol=1e-12)
    hole_id = app.constraints.add("hole", distance=0.08)  # default: the first arm
    assert app.constraints.entries[hole_id].constraint.link == dual.constrained_links[0]
    snapshot = app.view.snapshot()
    drawn = {entry["id"]: entry for entry in snapshot["constraints"]}
    for entry_id, on in ((lock_id, right), (hole_id, dual.constrained_links[0])):
        placement = data.oMf[dual.model.getFrameId(on)]
        assert drawn[entry_id]["link"] == on
        np.testing.assert_allclose(drawn[entry_id]["link_axis"],
                                   placement.rotation @ dual.link_axes[on], atol=1e-12)


def test_nudges_home_and_gizmo_to_target_act_on_one_ee(app, dual):
    targets = app.console.targets
    app.console.nudge_target([0.0, 0.0, 0.01], ee=1)
    np.testing.assert_allclose(app.console.inputs[1].target.translation,
                               targets[1].translation + [0, 0, 0.01], atol=1e-15)
    assert app.console.inputs[0].target.isApprox(targets[0], 1e-15)
    assert app.console.inputs[1].gizmo.isApprox(targets[1], 1e-15)  # the gizmo stayed
    app.console.gizmo_to_target("arm_right_link_tool0")  # by name as well
    assert app.console.inputs[1].gizmo.isApprox(app.console.inputs[1].target, 1e-15)
    for bad in (2, -1, "tool0", True, 0.5):
        with pytest.raises(ValueError, match="no end effector"):
            app.console.nudge_target([0.0, 0.0, 0.01], ee=bad)
    app.console.nudge_target([0.01, 0.0, 0.0], ee=0)
    app.constraints.add("hole", distance=0.08, link=dual.constrained_links[1])
    run(app, 0.3)
    app.console.home(ee=0)  # one EE's target home; the other keeps its own
    data = dual.model.createData()
    pin.framesForwardKinematics(dual.model, data, dual.q_home)
    home = [data.oMf[frame].copy() for frame in dual.ee_frame_ids]
    assert app.console.inputs[0].target.isApprox(home[0], 1e-12)
    np.testing.assert_allclose(app.console.inputs[1].target.translation,
                               home[1].translation + [0, 0, 0.01], atol=1e-12)
    # every EE, the constraint stays: the robot goes home on a path that keeps it
    assert app.console.home() == "" and app.homing.active
    while app.homing.active:
        app.step()
    assert all(app.console.inputs[k].target.isApprox(home[k], 1e-12) for k in (0, 1))
    assert len(app.constraints.entries) == 1


def test_clutch_and_motion_scale_act_on_every_gizmo(app):
    app.console.set_motion_scale(0.5)
    starts = app.console.targets
    app.console.set_clutch(True)
    for ee in (0, 1):  # repositioning both hands: no target moves
        gizmo = app.console.inputs[ee].gizmo
        app.console.move_gizmo(gizmo.translation + [0.05, 0.0, 0.0], wxyz(gizmo), ee)
    assert all(app.console.inputs[k].target.isApprox(starts[k], 1e-15) for k in (0, 1))
    app.console.set_clutch(False)
    for ee, step in ((0, [0.0, 0.02, 0.0]), (1, [0.0, 0.0, -0.04])):
        gizmo = app.console.inputs[ee].gizmo
        app.console.move_gizmo(gizmo.translation + step, wxyz(gizmo), ee)
        np.testing.assert_allclose(app.console.inputs[ee].target.translation,
                                   starts[ee].translation + 0.5 * np.asarray(step), atol=1e-12)


def test_a_scene_with_two_targets_and_two_holes_round_trips(app, dual, tmp_path):
    for link in dual.constrained_links:
        app.constraints.add("hole", distance=0.08, link=link)
    app.console.nudge_target([0.0, 0.005, 0.0], ee=1)
    run(app, 0.2)
    path = app.scenes.save("two.json")
    data = json.loads(path.read_text())
    assert [t["frame"] for t in data["targets"]] == list(dual.ee_frames)
    assert data["robot"]["ee_frames"] == list(dual.ee_frames)
    assert list(data["robot"]["constrained_links"]) == list(dual.constrained_links)
    again = robot_from_dict(data["robot"])
    assert again.ee_frames == dual.ee_frames and again.constrained_links == dual.constrained_links
    other = TeleopApp(again, record_dir=tmp_path, scene_dir=path.parent)
    other.scenes.load(path.name)
    for k in (0, 1):
        assert other.console.inputs[k].target.isApprox(app.console.inputs[k].target, 1e-12)
        assert other.console.inputs[k].gizmo.isApprox(app.console.inputs[k].target, 1e-12)
    assert [e.constraint.link for e in other.constraints.entries.values()] == list(dual.constrained_links)
    np.testing.assert_array_equal(other.robots.loops["main"].q, app.robots.loops["main"].q)
    run(other, 0.2)
    assert other.robots.last_records["main"].constraint_error <= HOLE_TOLERANCE
    # a two-EE robot needs both targets, named in order
    for targets, message in ((None, "one target per end effector"),
                             (list(reversed(data["targets"])), "in order")):
        broken = dict(data)
        broken.pop("targets")
        if targets is not None:
            broken["targets"] = targets
        with pytest.raises(ValueError, match=message):
            parse_scene(broken, dual.nq, dual.ee_frames)


def test_a_single_ee_scene_names_no_several_frames(sda10f, tmp_path):
    description = robot_to_dict(sda10f)
    assert not {"ee_frames", "constrained_links", "root_joint", "locked_joints"} & set(description)
    scene = TeleopApp(sda10f, record_dir=tmp_path).scenes.scene()
    assert "targets" not in scene


def test_a_locked_joint_robot_is_described_and_loaded_again(dual):
    locked = load_robot("sda10f_dual", locked_joints=["torso_joint_b1"])
    description = robot_to_dict(locked)
    assert description["locked_joints"] == {"torso_joint_b1": [0.0]}
    again = robot_from_dict(json.loads(json.dumps(description)))
    assert again.nq == 14 and dict(again.locked_joints) == dict(locked.locked_joints)
    np.testing.assert_array_equal(again.q_home, locked.q_home)
    assert same_robot(again, description) and not same_robot(dual, description)


def test_the_mobile_base_drives_and_a_wall_on_it_holds(mobile, tmp_path):
    """A wall (a barrier) 5 cm in front of the base's front edge; the targets pulled 30 cm
    forward, beyond where the arms alone would take them: the base drives up to the wall
    and never through it."""
    app = TeleopApp(mobile, controller="cjm", record_dir=tmp_path)
    links = app.constraints.moving_links
    assert links[:2] == mobile.constrained_links and "mobile_base" in links
    front = [0.4, 0.0, 0.15]  # the middle of the base's front face, base coordinates
    with pytest.raises(ValueError, match="mobile_base has no instrument axis"):
        app.constraints.add("barrier", distance=0.1, normal=[-1.0, 0.0, 0.0], link="mobile_base")
    with pytest.raises(ValueError, match="link point must be within 2 m"):
        app.constraints.add("plane", link_point=[5.0, 0.0, 0.0], normal=[-1.0, 0.0, 0.0],
                           link="mobile_base")
    wall_id = app.constraints.add("barrier", link_point=front, normal=[-1.0, 0.0, 0.0],
                                 offset=0.05, link="mobile_base")
    wall = app.constraints.entries[wall_id].constraint
    np.testing.assert_allclose(wall.position, [0.45, 0.0, 0.15], atol=1e-12)
    base = mobile.model.getFrameId("mobile_base")
    data = mobile.model.createData()
    penetration = 0.0
    for _ in range(60):  # 30 cm in 3 s, both targets
        for ee in (0, 1):
            app.console.nudge_target([0.005, 0.0, 0.0], ee)
        for _ in range(50):
            app.step()
            pin.framesForwardKinematics(mobile.model, data, app.robots.loops["main"].q)
            penetration = max(penetration, wall.violation(data.oMf[base]))
    run(app, 1.0)
    q = app.robots.loops["main"].q
    pin.framesForwardKinematics(mobile.model, data, q)
    edge = data.oMf[base].act(np.array(front))[0]
    print(f"\nmobile base: x {q[0]:.4f} m, front edge at {edge:.5f} m (wall at 0.45 m), "
          f"worst penetration {penetration:.2e} m")
    assert q[0] > 0.01, "the base did not drive"
    assert penetration <= 1e-6 and edge <= 0.45 + 1e-6


# -- the viser view (a real viser server, no browser: tests/test_browser_dual.py has one) ----


@pytest.fixture()
def server():
    import viser
    from browser_helpers import free_port

    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server
    server.stop()


def make_ui(server, app):
    from web.app import ControlThread
    from web.ui import TeleopUI

    return TeleopUI(server, app, ControlThread(app))


def test_a_gizmo_line_and_target_per_ee(server, app):
    from web.ui import STATUS_COLORS

    ui = make_ui(server, app)
    assert len(ui.scene.target_gizmos) == 2 and ui.ee_names == {"arm_left_link_tool0": "left",
                                                          "arm_right_link_tool0": "right"}
    assert ui.teleop_panel.active_arm.visible and ui.teleop_panel.active_arm.options == ("left", "right")
    for gizmo, target in zip(ui.scene.target_gizmos, app.console.targets):
        np.testing.assert_allclose(gizmo.position, target.translation, atol=1e-9)
    right = ui.scene.target_gizmos[1]  # what the right gizmo's drag does: the right target only
    right.position = np.asarray(right.position) + [0.0, -0.01, 0.0]
    ui.scene._gizmo_moved(right, 1)(SimpleNamespace(client=None, client_id=None, phase="update"))
    ui.inbox.start()  # the action went to the inbox: applied there
    try:
        assert ui.inbox.drain(10.0)
    finally:
        ui.inbox.stop()
    np.testing.assert_allclose(app.console.inputs[1].target.translation, right.position, atol=1e-12)
    assert app.console.inputs[0].target.isApprox(app.console.inputs[0].gizmo, 1e-15)
    for _ in range(20):
        app.step()
    snapshot = app.view.snapshot()
    ui._draw(snapshot)
    assert not ui.scene.reach_lines[0].visible and ui.scene.reach_lines[1].visible
    np.testing.assert_allclose(ui.scene.reach_lines[1].points[0],
                               [ee_positions(app)[1], app.console.inputs[1].target.translation], atol=1e-9)
    np.testing.assert_allclose(ui.scene.reach_lines[1].colors[0, 0], STATUS_COLORS["ok"])
    details = ui.status_panel.details.content
    assert "*left* on target" in details and "*right* moving to the target" in details
    ui.teleop_panel.active_arm.value = "right"  # the nudges act on the active arm
    ui.teleop_panel.nudge_buttons.value = "+z"
    before = app.console.targets
    app.console.nudge_target(0.005 * np.array([0.0, 0.0, 1.0]), ui.teleop_panel.active_ee())
    np.testing.assert_allclose(app.console.inputs[1].target.translation - before[1].translation,
                               [0, 0, 0.005], atol=1e-15)
    ui.teleop_panel.home()
    for gizmo, target in zip(ui.scene.target_gizmos, app.console.targets):
        np.testing.assert_allclose(gizmo.position, target.translation, atol=1e-9)


def test_each_nudge_is_the_one_clicked_however_late_the_inbox_applies_it(server, app):
    """Three clicks on the nudge buttons reach viser before the inbox applies the first (a
    busy machine): each nudge is its own button, step and arm, read as viser got the click.
    Read when the inbox applied them, all three were the last: +x by 2 mm on the right arm."""
    ui = make_ui(server, app)
    panel = ui.teleop_panel
    assert inspect.iscoroutinefunction(panel.nudge_clicked)  # awaited in viser's event loop
    before = [target.translation.copy() for target in app.console.targets]
    click = SimpleNamespace(client=None, client_id=None)
    for arm, label, step in (("left", "+y", 0.005), ("left", "-z", 0.005), ("right", "+x", 0.002)):
        panel.active_arm.value, panel.nudge_step.value = arm, step
        # what viser's handler of a click's message does: the group's value set (its state;
        # the public setter runs the callbacks itself), then the coroutine awaited
        panel.nudge_buttons._impl.value = label
        asyncio.run(panel.nudge_clicked(click))
    ui.inbox.start()
    try:
        assert ui.inbox.drain(10.0)
    finally:
        ui.inbox.stop()
    after = [target.translation for target in app.console.targets]
    np.testing.assert_allclose(after[0] - before[0], [0.0, 0.005, -0.005], atol=1e-15)
    np.testing.assert_allclose(after[1] - before[1], [0.002, 0.0, 0.0], atol=1e-15)
    for gizmo, target in zip(ui.scene.target_gizmos, after):  # each gizmo on its target
        np.testing.assert_allclose(gizmo.position, target, atol=1e-9)


def test_each_arms_hole_is_drawn_around_its_own_link(server, app, dual):
    ui = make_ui(server, app)
    ids = [app.constraints.add("hole", distance=0.08, link=link) for link in dual.constrained_links]
    snapshot = app.view.snapshot()
    ui._draw(snapshot)
    for hole_id, link in zip(ids, dual.constrained_links):
        ring = ui.constraint_markers.nodes[hole_id]["shape"].points
        centre = app.constraints.entries[hole_id].position
        radii = np.linalg.norm(ring.reshape(-1, 3) - centre, axis=1)
        radius = ui.constraint_drawer.ring_radius_at(
            snapshot["robots"]["main"]["constraints"][hole_id])
        np.testing.assert_allclose(radii, radius, atol=1e-6)  # float32
        frame = dual.model.getFrameId(link)
        assert radius > max(g.geometry.radius for g in dual.visual_model.geometryObjects
                            if g.parentFrame == frame and type(g.geometry).__name__ == "Cylinder")
        collar = ui.constraint_markers.nodes[hole_id]["point"].points.reshape(-1, 3)
        assert np.linalg.norm(collar.mean(axis=0) - centre) < 1e-3  # around the link at the hole


def test_the_mobile_base_is_drawn_where_the_planar_joint_puts_it_and_a_wall_spans_it(
        server, mobile, tmp_path):
    app = TeleopApp(mobile, record_dir=tmp_path)
    ui = make_ui(server, app)
    assert ui.floor == pytest.approx(0.0)  # the base's box stands on the floor
    q = app.robots.loops["main"].q.copy()
    q[:4] = [0.3, -0.2, np.cos(0.5), np.sin(0.5)]  # x, y, heading 0.5 rad
    app.robots.loops["main"].q = q
    ui._draw(app.view.snapshot())
    view = ui.scene.views["main"]
    geometry = pin.GeometryData(mobile.visual_model)
    pin.updateGeometryPlacements(mobile.model, mobile.model.createData(), mobile.visual_model,
                                 geometry, q)
    for index, geometry_object in enumerate(mobile.visual_model.geometryObjects):
        if geometry_object.parentFrame != mobile.model.getFrameId("mobile_base"):
            continue
        handle = view.frames[f"/main/visual/{geometry_object.name}"]
        np.testing.assert_allclose(handle.position, geometry.oMg[index].translation, atol=1e-6)
        np.testing.assert_allclose(np.abs(pin.Quaternion(geometry.oMg[index].rotation).coeffs()
                                          [[3, 0, 1, 2]] @ handle.wxyz), 1.0, atol=1e-6)
    wall_id = app.constraints.add("barrier", link_point=[0.4, 0.0, 0.15],
                                 normal=[-1.0, 0.0, 0.0], offset=0.05, link="mobile_base")
    ui._draw(app.view.snapshot())
    plane = ui.constraint_markers.nodes[wall_id]["shape"]
    assert plane.dimensions[0] == pytest.approx(1.6)  # twice the base's 0.8 m length
    np.testing.assert_allclose(plane.position, app.constraints.entries[wall_id].position, atol=1e-9)


def test_a_recorded_session_holds_both_targets_and_replays(app, dual, tmp_path):
    from teleop.experiments.compare import run_plan
    from teleop.experiments.sessions import load_session, session_plan

    for link in dual.constrained_links:
        app.constraints.add("hole", distance=0.08, link=link)
    path = app.start_recording("two.jsonl")
    app.console.nudge_target([0.0, 0.004, 0.0], ee=0)
    run(app, 0.2)
    app.console.nudge_target([0.0, 0.0, -0.004], ee=1)
    run(app, 0.2)
    app.stop_recording()
    session = load_session(path)
    frames = [event.get("frame", dual.ee_frames[0]) for event in session.events
              if event["type"] == "target"]
    assert frames.count(dual.ee_frames[1]) == 2 and frames.count(dual.ee_frames[0]) == 2
    metrics = run_plan(session_plan(session), "cjm").metrics()
    # 4 mm target jumps: the same bound as the single-arm session test
    assert metrics["failed_steps"] == 0 and metrics["constraint_error_max_m"] < 1e-5


@pytest.mark.parametrize("spec", ["cjm", pytest.param("qp:daqp", marks=pytest.mark.slow)])
def test_a_lower_orientation_weight_lets_the_dragged_tip_reach_its_target(dual, tmp_path, spec):
    """Two trocars leave 11 joint directions for two full poses (12): at orientation weight
    1 the dragged tip stops short (least squares); at 0 only the tips' positions are asked
    for, so the dragged tip reaches its target and the other stays, holes held."""
    reached = {}
    for weight in (1.0, 0.0):
        app = TeleopApp(dual, controller=spec, record_dir=tmp_path / "sessions",
                        scene_dir=tmp_path / "scenes")
        # the full poses: with the holes the default asks for position and roll, which
        # both tips meet at either weight (7.2e-11 m measured)
        app.robots.set_task_mode("pose")
        ids = [app.constraints.add("hole", distance=0.08, link=link)
               for link in dual.constrained_links]
        app.robots.set_orientation_weight(weight)
        assert app.robots.orientation_weight == weight
        start = ee_positions(app)
        displacement = np.array([0.0, 0.01, 0.01])
        drag(app, 0, displacement, steps=20, ticks_per_step=40)
        run(app, 1.5)  # 15 time constants of the gain kp = 20 1/s with the target filter
        end = ee_positions(app)
        reached[weight] = float(np.linalg.norm(end[0] - (start[0] + displacement)))
        model, data = dual.model, dual.model.createData()
        pin.framesForwardKinematics(model, data, app.robots.loops["main"].q)
        for hole_id in ids:
            hole = app.constraints.entries[hole_id].constraint
            assert hole.violation(data.oMf[model.getFrameId(hole.link)]) <= HOLE_TOLERANCE
        if weight == 0.0:
            assert np.linalg.norm(end[1] - start[1]) < 1e-4, "the other tip moved"
    assert reached[0.0] < 1e-4, reached  # the dragged tip where it was dragged
    assert reached[1.0] > 10 * reached[0.0], reached


def test_orientation_weight_is_checked_and_kept_in_scenes(app, tmp_path):
    for bad in (-0.1, 1.5, float("nan"), "x"):
        with pytest.raises(ValueError, match="orientation weight"):
            app.robots.set_orientation_weight(bad)
    assert app.robots.orientation_weight == 1.0
    app.robots.set_orientation_weight(0.25)
    path = app.scenes.save("scene.json")
    assert json.loads(path.read_text())["orientation_weight"] == 0.25
    app.robots.set_orientation_weight(1.0)
    app.scenes.load("scene.json")
    assert app.robots.orientation_weight == 0.25
    assert np.allclose(app.robots.loops["main"].controller.twist_weight, [1, 1, 1, 0.25, 0.25, 0.25] * 2)
