"""The viser view on a real viser server, without a browser: what it draws and where.

The view thread is not started: each test takes a snapshot of the app and draws it
(``ui._draw``, ``ui.plots.draw``) itself, then reads the scene nodes' and GUI handles' state.
What a browser makes of it is tests/test_browser.py's.
"""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
import viser
from browser_helpers import PANDA, free_port

from constraints import CONSTRAINT_TYPES
from teleop import load_robot
from web.app import ControlThread, TeleopApp
from web.robot_view import RobotView, floor_height
from web.ui import PLOTS, STATUS_COLORS, TeleopUI, reach_from_axis


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server
    server.stop()


@pytest.fixture()
def ui(sda10f, server, tmp_path):
    app = TeleopApp(sda10f, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes")
    return TeleopUI(server, app, ControlThread(app))


def run(app, seconds):
    for _ in range(int(seconds * app.robots.config.rate)):
        app.step()


def draw(ui, plot=False):
    snapshot = ui.app.view.snapshot()
    ui._draw(snapshot)
    if plot:
        ui.plots.draw(snapshot)
    return snapshot


def nudge(app, offset):
    target = app.console.target
    quaternion = pin.Quaternion(target.rotation)
    app.console.set_target(target.translation + offset,
                   [quaternion.w, quaternion.x, quaternion.y, quaternion.z])


def test_the_grid_is_at_the_robots_base(ui, ur5_instrument):
    assert ui.floor == pytest.approx(-0.1)  # the sda10f's base cylinder reaches 0.1 m down
    np.testing.assert_allclose(ui.scene.grid.position, [0.0, 0.0, -0.1])
    assert floor_height(ur5_instrument) == pytest.approx(-0.01)
    panda = load_robot(PANDA)
    assert floor_height(panda) == pytest.approx(0.0, abs=1e-6)  # link0's mesh stands on z = 0


def test_the_ghost_is_drawn_at_its_offset_with_its_own_constraints(ui):
    app = ui.app
    hole_id = app.constraints.add("hole", distance=0.08)
    app.robots.set_ghost("qp:daqp")
    nudge(app, [0.0, 0.01, 0.0])
    run(app, 0.1)
    draw(ui)
    assert "ghost" not in ui.scene.views  # the plots show a new ghost first (then its meshes)
    draw(ui, plot=True)
    draw(ui)
    offset = app.robots.ghost_offset
    np.testing.assert_allclose(ui.scene.ghost_root.position, offset)
    assert ui.scene.ghost_root.name == "/ghost"
    ghost = ui.scene.views["ghost"]
    names = [g.name for g in app.robot.visual_model.geometryObjects]
    assert all(f"/ghost/robot/visual/{name}" in ghost.frames for name in names)
    assert ui.scene.ghost_style == (0.45, 0.7, 1.0, 0.8)  # beside: nearly opaque
    # its own hole drawing, under the offset node, at its own link
    markers = ui.ghost_markers.nodes[hole_id]
    assert markers["shape"].name == f"/ghost/constraints/{hole_id}/ring"
    assert "gizmo" not in markers  # one gizmo per hole: the main robot's
    assert ui.constraint_markers.nodes[hole_id]["gizmo"].name == f"/constraints/{hole_id}/gizmo"
    # moved the ghost: the whole subtree goes with it
    app.robots.set_ghost_offset([0.0, -1.0, 0.0])
    draw(ui)
    np.testing.assert_allclose(ui.scene.ghost_root.position, [0.0, -1.0, 0.0])
    app.robots.set_ghost_offset([0.0, 0.0, 0.0])  # overlay: redrawn see-through
    draw(ui)
    assert ui.scene.ghost_style[3] < 0.5
    np.testing.assert_allclose(ui.scene.ghost_root.position, [0.0, 0.0, 0.0])
    app.robots.set_ghost(None)
    draw(ui)
    assert "ghost" not in ui.scene.views and not ui.ghost_markers.nodes


def test_a_satisfied_barrier_draws_no_error_line_and_an_arrow_to_its_allowed_side(ui):
    app = ui.app
    barrier_id = app.constraints.add("barrier", distance=0.05, normal=[0.0, 0.0, 1.0], offset=0.01)
    run(app, 0.05)
    draw(ui)
    markers = ui.constraint_markers.nodes[barrier_id]
    assert markers["error"].visible is False  # was a 1 m magenta line
    arrow = np.asarray(markers["arrow"].points)
    anchor = app.constraints.entries[barrier_id].position
    np.testing.assert_allclose(arrow[0, 0], anchor, atol=1e-6)  # viser keeps float32
    np.testing.assert_allclose(arrow[0, 1] - anchor, [0.0, 0.0, 0.08], atol=1e-6)  # +n, 8 cm
    assert ui.constraint_panel.inputs["plane"]["normal"].label == "plane normal (world)"
    assert "world coordinates" in ui.constraint_panel.inputs["plane"]["normal"].hint


def test_constraint_points_and_gizmos_are_visible_outside_the_link(ui):
    app = ui.app
    hole_id = app.constraints.add("hole", distance=0.08)
    lock_id = app.constraints.add("point_lock", distance=0.05)
    draw(ui)
    frame = app.robot.model.getFrameId(app.robot.constrained_link)
    link_radius = max(g.geometry.radius for g in app.robot.visual_model.geometryObjects
                      if g.parentFrame == frame and type(g.geometry).__name__ == "Cylinder")
    assert link_radius == pytest.approx(0.04)  # arm_link_5_r's cylinder
    assert reach_from_axis(app.robot, app.robot.constrained_link) >= link_radius
    for entry_id in (hole_id, lock_id):
        markers = ui.constraint_markers.nodes[entry_id]
        collar = np.asarray(markers["point"].points).reshape(-1, 3)
        point = app.view.snapshot()["robots"]["main"]["constraints"][entry_id]["geometry"].point
        radii = np.linalg.norm(collar - point, axis=1)
        assert radii.min() > link_radius + 0.005  # a collar around the link, not a dot inside
        assert markers["gizmo"].depth_test is False  # drawn over the link that hides its centre


def test_the_ee_target_line_takes_the_step_status_colour(ui):
    app = ui.app
    app.robots.set_task_mode("pose")  # position and roll reach this target (the default with a hole)
    app.constraints.add("hole", distance=0.08)
    draw(ui)
    assert ui.scene.reach_line.visible is False  # on target: nothing to show
    assert ui.scene.target_marker.visible is False  # the target is at the gizmo
    nudge(app, [0.5, 0.0, 0.0])  # out of reach through the hole
    run(app, 6.0)
    snapshot = draw(ui)
    limitation = snapshot["robots"]["main"]["limitation"]
    assert limitation.status == "least_squares" and "target out of reach" in limitation.details
    assert "short of the target" in limitation.words  # the part, the cause, the action
    assert ui.scene.reach_line.visible is True
    np.testing.assert_allclose(ui.scene.reach_line.points[0, 1], app.console.target.translation, atol=1e-6)
    np.testing.assert_allclose(ui.scene.reach_line.colors[0, 0], STATUS_COLORS["least_squares"])
    assert ui.scene.target_marker.visible is True  # drawn apart from the gizmo
    assert "short of the target" in ui.status_panel.details.content


def test_plots_are_finite_with_units_and_follow_the_ghost(ui):
    app = ui.app
    app.constraints.add("hole", distance=0.08)
    nudge(app, [0.004, 0.0, 0.0])
    run(app, 0.3)
    draw(ui, plot=True)
    assert set(ui.plots.handles) == {spec.key for spec in PLOTS if not spec.ghost_only}
    for plot in ui.plots.handles.values():
        assert len(plot.series) == 2 == len(plot.data)
        assert all(np.isfinite(column).all() and column.size == 15 for column in plot.data)
    t = ui.plots.handles["ee_error"].data[0]  # seconds before now, on a fixed 10 s axis
    assert -0.02 <= t[-1] <= 0.0 and t[-1] - t[0] == pytest.approx(0.28)  # 15 samples, 50 Hz
    assert np.all(np.diff(t) > 0)
    assert ui.plots.handles["ee_error"].scales["x"]["range"] == (-10.0, 0.0)
    title = ui.plots.handles["ee_error"].title
    assert title.startswith("EE position error (") and title.endswith("m)")
    ee = ui.plots.handles["ee_error"].data[1]
    assert 1.0 <= ee.max() < 2000.0  # readable numbers in the unit of the title
    app.robots.set_ghost("qp:daqp")
    run(app, 0.2)
    draw(ui, plot=True)
    assert set(ui.plots.handles) == {spec.key for spec in PLOTS}
    for plot in ui.plots.handles.values():
        assert all(np.isfinite(column).all() and column.size == 10 for column in plot.data)
    assert [s["label"] for s in ui.plots.handles["constraint_error"].series] == [
        "t - now (s)", "main (cjm)", "ghost (qp:daqp)"]
    app.robots.set_ghost(None)
    draw(ui, plot=True)
    assert "qd_deviation" not in ui.plots.handles
    assert len(ui.plots.handles["constraint_error"].series) == 2


def test_loading_a_scene_sets_the_widgets(ui, tmp_path):
    app = ui.app
    app.constraints.add("hole", distance=0.08)
    app.robots.set_gain(60.0)
    app.console.set_motion_scale(0.5)
    app.robots.set_ghost("qp:daqp")
    app.robots.set_task_mode("position")
    ui.settings_panel.scene_path.value = "s.json"
    ui.settings_panel.save_scene()
    assert ui.settings_panel.scene_status.content == "saved `s.json`"
    assert (tmp_path / "scenes" / "s.json").is_file()
    app.robots.set_gain(100.0)
    app.console.set_motion_scale(1.0)
    app.robots.set_ghost(None)
    app.robots.set_task_mode("auto")
    app.constraints.clear()
    ui.settings_panel.load_scene()
    assert list(app.constraints.entries) == ["hole-1"] and app.robots.gain == 60.0
    assert app.robots.task_mode == "position" and ui.teleop_panel.task_mode_menu.value == "position only"
    assert app.robots.loops["main"].task_modes == app.robots.loops["ghost"].task_modes == ("position",)
    assert ui.settings_panel.gain_slider.value == 60.0
    assert ui.teleop_panel.motion_scale.value == 0.5
    panel = ui.teleop_panel
    assert panel.side_by_side.value is True and panel.ghost_menu.value == "qp:daqp"
    np.testing.assert_allclose(panel.ghost_offset.value, app.robots.ghost_offset)


def test_the_panda_draws_its_meshes(server):
    panda = load_robot(PANDA, ee_frame="panda_hand")
    view = RobotView(panda, server, "/panda")
    assert view.problems == []
    for geometry in panda.visual_model.geometryObjects:
        handle = view.frames[f"/panda/visual/{geometry.name}"]
        assert type(handle).__name__ == "GlbHandle"  # the .dae with its materials


def test_a_mesh_that_cannot_be_read_falls_back_and_says_so(server, monkeypatch, sda10f, tmp_path):
    import trimesh

    def no_collada(*args, **kwargs):
        raise ImportError("missing `pip install pycollada`")

    monkeypatch.setattr(trimesh, "load_scene", no_collada)
    panda = load_robot(PANDA, ee_frame="panda_hand")
    app = TeleopApp(panda, record_dir=tmp_path)
    ui = TeleopUI(server, app, ControlThread(app))
    view = ui.scene.views["main"]
    assert len(view.problems) == len(panda.visual_model.geometryObjects)
    assert view.problems[0] == ("link0.dae: missing `pip install pycollada`; drawn from the "
                                "mesh Pinocchio read, without its materials")
    for geometry in panda.visual_model.geometryObjects:  # every one drawn, as a plain mesh
        assert type(view.frames[f"/main/visual/{geometry.name}"]).__name__ == "MeshHandle"
    assert ui.notes == view.problems  # told to every browser that connects
    draw(ui)  # and it moves like any other


def test_a_robot_without_geometry_is_a_skeleton(server, tmp_path):
    urdf = tmp_path / "panda.urdf"
    urdf.write_text(PANDA.read_text())  # package:// meshes not found from here
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        panda = load_robot(urdf, ee_frame="panda_hand")
    assert [str(w.message).split(" (")[0].split(": ", 1)[1] for w in caught] == [
        "could not load the visual geometry", "could not load the collision geometry"]
    view = RobotView(panda, server, "/bare")
    assert view.problems == ["no geometry could be loaded: drawing a skeleton"]
    spheres = [name for name in view.frames if "skeleton_joint_" in name]
    assert len(spheres) == panda.model.njoints - 1
    view.display(panda.q_home)


def test_a_drag_ended_by_a_lost_browser_holds_the_target_where_the_ee_is(ui):
    """viser ends the drag of a browser that went away (its client no longer listed):
    its pending moves are dropped and the target held where the EE is."""
    from types import SimpleNamespace

    app = ui.app
    gizmo = ui.scene.target_gizmos[0]
    moved = ui.scene._gizmo_moved(gizmo, 0)
    gone = 12345  # a client id the server does not list
    assert gone not in ui.server.get_clients()
    start = app.console.target.translation.copy()
    ui.inbox.post(lambda: app.console.set_target(start + [0.0, 0.0, 0.02], [1, 0, 0, 0]))
    gizmo.position = np.asarray(gizmo.position) + [0.0, 0.0, 0.05]
    moved(SimpleNamespace(client=None, client_id=gone, phase="update"))  # ignored: gone
    moved(SimpleNamespace(client=None, client_id=gone, phase="end"))
    ui.inbox.start()
    try:
        assert ui.inbox.drain(10.0)
    finally:
        ui.inbox.stop()
    ee = app.robots.loops["main"].ee_placement()
    np.testing.assert_allclose(app.console.target.translation, ee.translation, atol=1e-12)
    np.testing.assert_allclose(gizmo.position, ee.translation, atol=1e-6)  # float32


def test_the_pandas_hole_ring_is_outside_its_link_mesh(server, tmp_path):
    """The ring goes around panda_link4 outside its mesh where it is: wider than every
    vertex of the link's visual and collision meshes within 1 cm of the ring's plane
    (world frame, from Pinocchio's geometry placements)."""
    panda = load_robot(PANDA, ee_frame="panda_hand", constrained_link="panda_link4",
                       link_axis=(-0.0825, 0.384, 0.0))
    app = TeleopApp(panda, record_dir=tmp_path)
    ui = TeleopUI(server, app, ControlThread(app))
    hole_id = app.constraints.add("hole", distance=0.08)
    snapshot = draw(ui)
    ring = np.asarray(ui.constraint_markers.nodes[hole_id]["shape"].points).reshape(-1, 3)
    geometry = snapshot["robots"]["main"]["constraints"][hole_id]["geometry"]
    centre, axis = geometry.anchor, geometry.axis / np.linalg.norm(geometry.axis)
    ring_radius = np.linalg.norm(ring - centre, axis=1).min()
    frame = panda.model.getFrameId("panda_link4")
    q = app.robots.loops["main"].q
    nearest = 0.0
    for model in (panda.visual_model, panda.collision_model):
        data = pin.GeometryData(model)
        pin.updateGeometryPlacements(panda.model, panda.model.createData(), model, data, q)
        for index, geometry_object in enumerate(model.geometryObjects):
            if geometry_object.parentFrame != frame:
                continue
            vertices = np.asarray(geometry_object.geometry.vertices())
            world = vertices @ data.oMg[index].rotation.T + data.oMg[index].translation
            offset = world - centre
            along = offset @ axis
            radial = np.linalg.norm(offset - np.outer(along, axis), axis=1)
            near = np.abs(along) < 0.01
            assert near.any()
            nearest = max(nearest, radial[near].max())
    print(f"\n[panda] ring radius {1e3 * ring_radius:.1f} mm around a mesh reaching "
          f"{1e3 * nearest:.1f} mm from the axis at the ring")
    assert ring_radius > nearest > 0.03


def test_every_kind_is_added_from_its_inputs_as_they_start(ui):
    """Each type's "Add" button with its inputs untouched places it where the link point is
    (before the declarations, "Add plane" took the barrier's offset and was refused)."""
    app = ui.app
    added = {kind: ui.constraint_panel.add(kind) for kind in ui.constraint_panel.inputs}
    assert set(added) == set(CONSTRAINT_TYPES) and len(app.constraints.entries) == len(CONSTRAINT_TYPES)
    data = app.robot.model.createData()
    pin.framesForwardKinematics(app.robot.model, data, app.robots.loops["main"].q)
    link = data.oMf[app.robot.model.getFrameId(app.robot.constrained_link)]
    for kind, entry_id in added.items():
        constraint = app.constraints.entries[entry_id].constraint
        inputs = ui.constraint_panel.inputs[kind]
        point = link.act(inputs["distance"].value * np.asarray(app.robot.link_axis))
        np.testing.assert_allclose(constraint.point_world(link), point, atol=1e-12)
        assert constraint.violation(link) <= 1e-12


def test_every_drawn_robot_has_its_contact_arrow_and_tissue(sda10f, server, tmp_path):
    """With a ghost beside the main robot, each presses the tissue in its own plant: each
    gets its plate and its arrow (the ghost's under /ghost, drawn at the offset), the
    arrow the one of its own tip and contact force; the ghost's go with the ghost."""
    from web.ui.force_panel import contact_arrow

    app = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path / "sessions",
                    scene_dir=tmp_path / "scenes")
    ui = TeleopUI(server, app, ControlThread(app))
    app.robots.set_ghost("qp:daqp")
    app.force.place_tissue()
    app.force.set_enabled(True)
    run(app, 3.0)  # 2 mm at 1 cm/s, then the force loop settles
    draw(ui, plot=True)
    snapshot = draw(ui)
    assert set(ui.scene.views) == {"main", "ghost"}
    contacts = snapshot["force"]["contacts"]
    panel = ui.force_panel
    assert set(panel.arrows) == set(panel.tissues) == {"main", "ghost"}
    for which, prefix in (("main", "/force"), ("ghost", "/ghost/force")):
        force = contacts[which]["contact"]
        assert np.linalg.norm(force) == pytest.approx(1.0, abs=0.05)  # each presses 1 N
        arrow = panel.arrows[which]
        assert arrow.name == f"{prefix}/contact" and arrow.visible
        np.testing.assert_allclose(arrow.points, contact_arrow(contacts[which]["tip"], force),
                                   atol=1e-6)  # float32 on the wire
        assert panel.tissues[which].name == f"{prefix}/tissue"
    assert panel.arrow is panel.arrows["main"]
    app.robots.set_ghost(None)
    draw(ui)
    assert set(panel.arrows) == set(panel.tissues) == {"main"}
