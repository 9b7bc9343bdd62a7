"""End to end, the operator's console: a real Chromium against the real `teleop web` server.

Started as ``teleop web --ghost qp:daqp`` would: the live plots draw both robots' lines
within 3 s, the ghost is drawn at its offset beside the main robot, the clutch decouples a
real mouse drag of the gizmo from the robot (and its release does not move the target), a
scene saved from the page and loaded back restores the constraints and settings, an
out-of-range hole distance becomes a notification. Every wait is bounded
(tests/browser_helpers.py).
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import (  # noqa: F401 (watchdog: an autouse fixture)
    press,
    WAIT,
    canvas_pixels,
    changed_fraction,
    click_add_hole,
    distinct_colours,
    drag,
    ee_position,
    hex_rgb,
    input_of,
    look_at_target,
    open_tab,
    open_web,
    plan_drag,
    project,
    scene_canvas,
    set_camera,
    uplot_line_pixels,
    wait_for_pixels,
    wait_for_still_canvas,
    wait_until,
    watchdog,
)
from playwright.sync_api import expect

from teleop import load_robot
from web.ui import GHOST_COLOR, MAIN_COLOR

PLOT_DEADLINE = WAIT  # s: the live plots draw their lines (measured and printed)


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    """``teleop web --ghost qp:daqp`` and one Chromium page on it."""
    with open_web(load_robot("sda10f"), tmp_path_factory.mktemp("sessions"),
                  ghost="qp:daqp") as served:
        yield served


def test_plots_with_a_ghost_from_the_start_draw_within_3_s(web):
    started = time.perf_counter()
    open_tab(web, "Plots")

    def lines():
        main = uplot_line_pixels(web.page, hex_rgb(MAIN_COLOR))
        ghost = uplot_line_pixels(web.page, hex_rgb(GHOST_COLOR))
        # five plots; the ghost's line in each (it is drawn over the main one where they
        # agree), the main robot's where they differ (the step times)
        if len(ghost) == 5 and min(ghost) >= 15 and main[3] >= 15:  # lines, however short
            return main, ghost
        return None

    main, ghost = wait_until(lines, PLOT_DEADLINE, "both robots' plot lines", 0.05)
    print(f"\n[browser] with a ghost: plot lines after {time.perf_counter() - started:.2f} s; "
          f"main pixels {main}, ghost pixels {ghost}")


def robot_points(app, which: str) -> np.ndarray:
    """World positions of every joint of robot ``which``, where it is drawn."""
    model = app.robot.model
    data = model.createData()
    with app._lock:
        q = app.robots.loops[which].q.copy()
    pin.forwardKinematics(model, data, q)
    points = np.array([placement.translation for placement in data.oMi[1:]])
    return points + (app.robots.ghost_offset if which == "ghost" else 0.0)


def test_the_ghost_is_drawn_beside_the_robot_at_its_offset(web):
    app, ui = web.app, web.ui
    offset = app.robots.ghost_offset
    assert np.linalg.norm(offset) > 0.5 and abs(offset[2]) < 1e-12
    main, ghost = robot_points(app, "main"), robot_points(app, "ghost")
    centre = 0.5 * (main.mean(axis=0) + ghost.mean(axis=0))
    side = offset / np.linalg.norm(offset)
    front = np.cross(side, [0.0, 0.0, 1.0])
    set_camera(web.client, centre + 1.6 * front + np.array([0.0, 0.0, 0.6]), centre)
    box = scene_canvas(web.page)
    main_points = project(web.client.camera, box, main) - (box.x, box.y)
    ghost_points = project(web.client.camera, box, ghost) - (box.x, box.y)
    main_px, ghost_px = main_points.mean(axis=0), ghost_points.mean(axis=0)
    # apart on the screen, not overlaid: every joint of the ghost lies beyond every joint of
    # the main robot along the screen direction from one to the other
    apart = (ghost_px - main_px) / np.linalg.norm(ghost_px - main_px)
    assert (ghost_points @ apart).min() > (main_points @ apart).max()
    wait_for_pixels(web, lambda p: distinct_colours(p) > 100, WAIT, "the robots")
    # both images settled: a frame caught while the camera or the main robot still moves
    # changes pixels everywhere, and their centre says nothing about the ghost
    shown = wait_for_still_canvas(web, WAIT)
    ui.scene.views["ghost"].displayVisuals(False)
    try:
        wait_for_pixels(web, lambda p: changed_fraction(p, shown) > 0.005, WAIT,
                        "the canvas to change when the ghost is hidden")
        hidden = wait_for_still_canvas(web, WAIT)
    finally:
        ui.scene.views["ghost"].displayVisuals(True)
    # only the pixels around the two robots: the panel and the toasts overlay the canvas in a
    # screenshot, and their text changes on its own (a "control loop behind" notice on a
    # loaded machine moved the centre of all changed pixels halfway to the panel)
    both = np.vstack([main_points, ghost_points])
    around = 0.25 * (both.max(axis=0) - both.min(axis=0))
    (left, top), (right, bottom) = both.min(axis=0) - around, both.max(axis=0) + around
    rows, cols = np.nonzero(np.abs(hidden - shown).max(axis=2) > 24)
    near = (cols >= left) & (cols <= right) & (rows >= top) & (rows <= bottom)
    rows, cols = rows[near], cols[near]
    changed = np.array([cols.mean(), rows.mean()])
    print(f"\n[browser] ghost pixels centred at {changed.round()}, projected ghost "
          f"{ghost_px.round()}, main robot {main_px.round()}")
    assert np.linalg.norm(changed - ghost_px) < 0.3 * np.linalg.norm(changed - main_px)
    # the changed pixels are centred within the ghost's own extent on the screen
    low, high = ghost_points.min(axis=0), ghost_points.max(axis=0)
    margin = 0.25 * (high - low)
    assert np.all(low - margin <= changed) and np.all(changed <= high + margin), (changed, low, high)


def test_clutch_engaged_a_real_drag_does_not_move_the_robot_and_release_does_not_jump(web):
    app, page, ui = web.app, web.page, web.ui
    open_tab(web, "Teleop")
    press(web, "Clutch", ui.teleop_panel.clutch_button, lambda: app.console.clutch,
          "the clutch to engage")
    expect(page.get_by_role("button", name="Release clutch")).to_be_visible()
    time.sleep(0.5)
    target0, ee0 = app.console.target.copy(), ee_position(app)
    gizmo0 = np.asarray(ui.scene.target_gizmo.position).copy()
    look_at_target(web)
    plan = plan_drag(web, distance=0.01, steps=10)
    drag(web, plan)  # the real mouse, on the gizmo's arrow
    moved = wait_until(lambda: np.linalg.norm(app.console.gizmo.translation - gizmo0) > 0.005, WAIT,
                       "the gizmo to follow the mouse")
    assert moved
    time.sleep(0.5)
    assert app.console.target.isApprox(target0, 1e-12), "the target moved with the clutch engaged"
    assert np.linalg.norm(ee_position(app) - ee0) < 1e-6, "the robot moved"
    assert ui.scene.target_marker.visible  # the target drawn apart from the gizmo
    press(web, "Release clutch", ui.teleop_panel.clutch_button, lambda: not app.console.clutch,
          "the clutch to release")
    assert app.console.target.isApprox(target0, 1e-12), "the target jumped on release"
    time.sleep(0.3)
    assert np.linalg.norm(ee_position(app) - ee0) < 1e-6
    # a drag after the release moves the target by the drag, from where the target was
    gizmo1 = app.console.gizmo.translation.copy()
    plan = plan_drag(web, distance=0.006, steps=6, prefer_sign=-1.0)
    drag(web, plan)
    wait_until(lambda: np.linalg.norm(app.console.target.translation - target0.translation) > 0.003,
               WAIT, "the target to follow the drag after the release")
    time.sleep(0.3)
    np.testing.assert_allclose(app.console.target.translation - target0.translation,
                               app.console.gizmo.translation - gizmo1, atol=1e-9)
    wait_until(lambda: np.linalg.norm(ee_position(app) - app.console.target.translation) < 1e-4, WAIT,
               "the EE to reach the target")


def test_a_scene_saved_and_loaded_in_the_page_restores_constraints_and_settings(web, tmp_path):
    app, page = web.app, web.page
    hole_id = click_add_hole(web)
    goal = app.constraints.entries[hole_id].goal.copy()
    path = web.app.scene_dir / "my scene.json"
    open_tab(web, "Settings")
    input_of(page, "scene name").fill(path.name)
    wait_until(lambda: web.ui.settings_panel.scene_path.value == path.name, WAIT, "the scene name")
    press(web, "Save scene", web.ui.settings_panel.save_scene_button, path.exists, "the scene file")
    expect(page.get_by_text("saved", exact=False).first).to_be_visible()
    # change things from the page: the rate, the motion scale, the constraints
    input_of(page, "rate (Hz)").fill("500")
    wait_until(lambda: app.robots.config.rate == 500.0, WAIT, "the rate to change")
    open_tab(web, "Teleop")
    input_of(page, "motion scale").fill("0.2")
    wait_until(lambda: app.console.motion_scale == 0.2, WAIT, "the motion scale to change")
    open_tab(web, "Constraints")
    press(web, "Clear constraints", web.ui.constraint_panel.clear_button,
          lambda: not app.constraints.entries, "the constraints to be cleared")
    open_tab(web, "Settings")
    press(web, "Load scene", web.ui.settings_panel.load_scene_button,
          lambda: hole_id in app.constraints.entries, "the scene's hole")
    np.testing.assert_allclose(app.constraints.entries[hole_id].goal, goal, atol=1e-12)
    assert app.robots.config.rate == 1000.0 and app.console.motion_scale == 1.0
    assert app.robots.specs == {"main": "cjm", "ghost": "qp:daqp"}
    expect(input_of(page, "rate (Hz)")).to_have_value("1000")
    open_tab(web, "Constraints")
    expect(page.get_by_label("placed")).to_have_value(hole_id)
    time.sleep(0.5)
    assert app.robots.last_records["main"].constraint_error < 1e-6
    assert web.page_errors == [], web.page_errors


def test_an_out_of_range_hole_distance_shows_a_notification(web):
    app, page = web.app, web.page
    open_tab(web, "Constraints")
    before = list(app.constraints.entries)
    input_of(page, "hole at (m)").fill("5")
    distance = web.ui.constraint_panel.inputs["hole"]["distance"]
    wait_until(lambda: distance.value == 5.0, WAIT, "the distance 5 m")
    applied = web.ui.inbox.applied
    press(web, "Add hole", web.ui.constraint_panel.add_buttons["hole"],
          lambda: web.ui.inbox.applied > applied, "the hole to be refused")
    expect(page.get_by_text("hole distance must be between 0 and", exact=False).first
           ).to_be_visible()
    assert "Traceback" not in page.inner_text("body")
    assert list(app.constraints.entries) == before
    input_of(page, "hole at (m)").fill("0.08")
