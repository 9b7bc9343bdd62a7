"""End to end: the real `teleop web` server driven by a real (headless) Chromium.

The server runs in-process (``run_server``), the browser is Playwright's Chromium with
software WebGL (SwiftShader), so these tests need no GPU and no display. They check what
an operator sees and does: the page loads and registers as a viser client (viser counts a
browser only once its WebGL view is up), the robot is drawn, the live plots draw their
lines (read from the uPlot canvases), a *real mouse drag* of the target gizmo moves the end
effector while a hole holds the link (constraint error <= 1e-6 m), "Add hole" creates a hole
and its ring, the controller menu switches the controller, an impossible action becomes a
notification, and the README's screenshot is taken. tests/test_browser_console.py drives
the console features (clutch, scenes, the ghost beside the robot) and the Panda's meshes.

Dragging the gizmo: the test puts the browser's camera at a known pose (and waits until
the browser reports that pose back), projects a point of one translation arrow of the
gizmo onto the canvas with that camera (tests/browser_helpers.py: ``project``), presses
the mouse there and moves it along the arrow's projected direction in 1 mm steps. Steps
matter: each pointer move jumps the target, and the faster the robot then moves, the larger
the hole error the discrete-time (1 kHz) integration leaves before the drift feedback takes
it back: about 0.4 um for 1 mm jumps, 1.3 um for 2 mm, 17 um for 1 cm (same with qp:daqp).

Every wait is bounded. Run with ``-s`` to see the measured control rate and latencies.
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import (  # noqa: F401 (watchdog: an autouse fixture)
    press,
    choose,
    ARTIFACTS,
    close_notifications,
    WAIT,
    VIEWPORT,
    canvas_pixels,
    changed_fraction,
    click_add_hole,
    distinct_colours,
    ensure_hole,
    hex_rgb,
    look_at_target,
    measured_drag,
    open_status_details,
    open_tab,
    open_web,
    png_pixels,
    project,
    report_drag,
    scene_canvas,
    set_camera,
    trace_since,
    uplot_line_pixels,
    wait_for_pixels,
    wait_for_still_canvas,
    wait_until,
    watchdog,
    worst_of_trace,
)
from playwright.sync_api import expect

from teleop import load_robot
from web.ui import GHOST_COLOR, MAIN_COLOR
from web.ui.teleop_panel import NUDGES

HOLE_TOLERANCE = 1e-6  # m
PLOT_DEADLINE = WAIT  # s: the live plots draw their lines (measured and printed)


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    """The real server and one Chromium page connected to it (browser_helpers.open_web)."""
    with open_web(load_robot("sda10f"), tmp_path_factory.mktemp("sessions")) as served:
        yield served


# -- the tests ---------------------------------------------------------------------------------

def test_page_loads_and_the_browser_registers_as_a_client(web):
    assert web.response is not None and web.response.ok
    assert web.page.title() == "Viser"
    clients = web.server.get_clients()
    assert len(clients) == 1  # registered: viser counts a client once its WebGL view is up
    expect(web.page.get_by_text("Status", exact=True)).to_be_visible()
    for tab in ("Teleop", "Constraints", "Settings", "Plots"):
        expect(web.page.get_by_role("tab", name=tab, exact=True)).to_be_visible()
    camera = web.client.camera  # the browser reports its camera: the 3D view is running
    box = scene_canvas(web.page)
    assert camera.fov > 0 and (camera.image_width, camera.image_height) == (round(box.width),
                                                                           round(box.height))
    # the view thread publishes the status line, and the details (control rate) a click away
    expect(web.page.get_by_text("on target", exact=False).first).to_be_visible()
    open_status_details(web)
    expect(web.page.get_by_text("Hz achieved")).to_be_visible()
    expect(web.page.get_by_text("lateness p99", exact=False)).to_be_visible()
    time.sleep(3.0)  # a few seconds with the browser connected and drawing
    timing = web.control.timing()
    print(f"\n[browser] control with the browser connected: {timing.achieved_rate:.0f} Hz "
          f"(target {1.0 / web.app.robots.config.dt:.0f} Hz), lateness p50 "
          f"{timing.lateness_p50_ms:.3f} ms, p99 {timing.lateness_p99_ms:.3f} ms, tick p50 "
          f"{timing.tick_p50_us:.0f} us ({timing.overhead_p50_us:.0f} us beyond the "
          f"controller), {timing.deadline_misses} deadline misses")
    assert timing.ticks > 1000 and np.isfinite(timing.lateness_p99_ms)


def test_robot_is_in_the_scene(web):
    visualiser = web.ui.scene.views["main"]
    visual = [g.name for g in web.robot.visual_model.geometryObjects]
    assert visual, "the robot has no visual geometry"
    for name in visual:
        handle = visualiser.frames.get(f"/main/visual/{name}")
        assert handle is not None, f"visual {name} is not in the scene"
        assert handle.visible
    assert visualiser.visualRootFrame.visible

    # what the browser draws: not blank, and the robot is a good part of it
    look_at_target(web, distance=1.0)
    wait_for_pixels(web, lambda p: distinct_colours(p) > 100 and p.std() > 10.0, WAIT,
                    "a canvas that is not blank")
    shown = wait_for_still_canvas(web, WAIT)
    assert distinct_colours(shown) > 100 and shown.std() > 10.0
    visualiser.displayVisuals(False)
    try:
        hidden = wait_for_pixels(web, lambda p: changed_fraction(p, shown) > 0.01, WAIT,
                                 "the canvas to change when the robot is hidden")
    finally:
        visualiser.displayVisuals(True)
    fraction = changed_fraction(hidden, shown)
    wait_for_pixels(web, lambda p: changed_fraction(p, shown) < 0.25 * fraction, WAIT,
                    "the robot to be drawn again")
    print(f"\n[browser] the robot covers {100 * fraction:.1f} % of the canvas; "
          f"{distinct_colours(shown)} distinct colours")


def wait_for_plot_lines(web, colors: dict[str, tuple[int, int, int]], count: int,
                        since: float, minimum: int = 60) -> dict[str, list[int]]:
    """Until ``count`` uPlot canvases each hold at least ``minimum`` pixels of every colour
    in ``colors`` (read from the canvases), at most PLOT_DEADLINE s after ``since``."""
    def lines():
        found = {name: uplot_line_pixels(web.page, rgb) for name, rgb in colors.items()}
        drawn = all(len(c) == count and min(c) >= minimum for c in found.values())
        return found if drawn else None

    found = wait_until(lines, PLOT_DEADLINE - (time.perf_counter() - since),
                       f"{count} live plots to draw their {', '.join(colors)} lines", 0.05)
    print(f"\n[browser] plot lines drawn {time.perf_counter() - since:.2f} s after the "
          f"request; pixels of each line per plot: {found}")
    return found


def test_live_plots_draw_their_lines_within_3_s(web):
    started = time.perf_counter()
    open_tab(web, "Plots")
    wait_for_plot_lines(web, {"main": hex_rgb(MAIN_COLOR)}, count=4, since=started)
    titles = web.page.locator(".uplot .u-title").all_inner_texts()
    assert titles[0] == "constraint error (nm)" and titles[3] == "controller step time (µs)", titles
    assert web.page_errors == [], web.page_errors


def test_add_hole_button_creates_a_hole_and_its_ring(web):
    app = web.app
    # look at the constrained link, where the hole will be, to see the ring appear
    robot = web.robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, app.robots.loops["main"].q)
    link = data.oMf[robot.model.getFrameId(robot.constrained_link)]
    centre = link.act(0.08 * np.asarray(robot.link_axis))
    set_camera(web.client, centre + np.array([0.25, -0.3, 0.2]), centre)
    box = scene_canvas(web.page)
    u, v = project(web.client.camera, box, [centre])[0] - (box.x, box.y)
    half = 150  # px: the ring (5.5 cm) seen from 0.44 m is about 130 px across
    crop = (slice(max(0, int(v) - half), int(v) + half),
            slice(max(0, int(u) - half), int(u) + half))

    def orange(pixels) -> int:  # the ring's colour, (255, 170, 0)
        r, g, b = (pixels[crop][..., i] for i in range(3))
        return int(np.sum((r > 200) & (g > 110) & (g < 210) & (b < 90)))

    before = orange(canvas_pixels(web))
    hole_id = click_add_hole(web)
    entry = app.constraints.entries[hole_id]
    assert entry.kind == "hole"
    assert np.linalg.norm(entry.goal - centre) < 1e-6  # "hole at (m)" = 0.08 on the link axis
    markers = wait_until(lambda: web.ui.constraint_markers.nodes.get(hole_id), WAIT, "the hole's markers")
    assert markers["shape"].name == f"/constraints/{hole_id}/ring"
    ring = np.asarray(markers["shape"].points)
    assert ring.shape[1:] == (2, 3)
    radius = np.linalg.norm(ring.reshape(-1, 3) - entry.goal, axis=1)
    drawing = app.view.snapshot()["robots"]["main"]["constraints"][hole_id]
    assert np.allclose(radius, web.ui.constraint_drawer.ring_radius_at(drawing), atol=1e-6)
    # around the link, not hidden inside it
    link_radius = max(g.geometry.radius for g in robot.visual_model.geometryObjects
                      if g.parentFrame == robot.model.getFrameId(robot.constrained_link)
                      and type(g.geometry).__name__ == "Cylinder")
    assert radius.min() > link_radius
    expect(web.page.get_by_label("placed")).to_have_value(hole_id)
    after = wait_for_pixels(web, lambda p: orange(p) > before + 30, WAIT,
                            "the orange ring to be drawn in the page")
    print(f"\n[browser] hole {hole_id}: {orange(after)} orange ring pixels around its centre")


def test_real_mouse_drag_moves_the_ee_while_the_hole_holds(web):
    app = web.app
    ensure_hole(web)
    since = web.hole_time if web.hole_time is not None else app.now
    look_at_target(web)
    result = measured_drag(web, distance=0.012, steps=12)
    report_drag("drag, cjm", result, web.control)

    dragged = result.target1 - result.target0
    assert np.linalg.norm(dragged) > 0.01, "the target moved less than 1 cm"
    # along the arrow that was dragged, by about the planned amount
    assert abs(dragged @ result.plan.direction - 0.012) < 0.003
    assert np.linalg.norm(np.cross(dragged, result.plan.direction)) < 0.002
    # the gizmo the page moved is where the app's target is
    np.testing.assert_allclose(web.ui.scene.target_gizmo.position, result.target1, atol=1e-6)
    unit = dragged / np.linalg.norm(dragged)
    assert (result.ee1 - result.ee0) @ unit > 0.005, "the EE did not follow the target"
    assert np.linalg.norm(result.ee1 - result.target1) < 1e-3

    assert result.max_sampled_error <= HOLE_TOLERANCE
    trace = trace_since(app, since)
    assert trace["t"].size > 20
    assert trace["constraint_error"].max() <= HOLE_TOLERANCE, trace["constraint_error"].max()
    assert web.control.error is None


def test_switching_controller_in_the_page_keeps_the_hole(web):
    app, page = web.app, web.page
    ensure_hole(web)
    assert app.robots.specs["main"] == "cjm"
    open_tab(web, "Teleop")
    menu = page.get_by_label("main", exact=True)
    choose(web, "main", "qp:daqp")
    wait_until(lambda: app.robots.specs["main"] == "qp:daqp", WAIT, "the app to switch to qp:daqp")
    expect(menu).to_have_value("qp:daqp")
    switched = app.now
    assert "qp" in type(app.robots.loops["main"].controller).__name__.lower()
    # held still, then dragged back: the QP holds the hole too
    time.sleep(0.5)
    look_at_target(web)
    result = measured_drag(web, distance=0.006, steps=6, prefer_sign=-1.0)
    report_drag("drag, qp:daqp", result, web.control)
    assert np.linalg.norm(result.target1 - result.target0) > 0.004
    unit = (result.target1 - result.target0) / np.linalg.norm(result.target1 - result.target0)
    assert (result.ee1 - result.ee0) @ unit > 0.003
    assert result.max_sampled_error <= HOLE_TOLERANCE
    trace = trace_since(app, switched)
    assert trace["constraint_error"].max() <= HOLE_TOLERANCE, worst_of_trace(trace, switched, result)
    assert app.robots.last_records["main"] is not None and not app.robots.last_records["main"].failed


def test_impossible_action_shows_a_notification(web):
    app, page, ui = web.app, web.page, web.ui
    planes_before = [e for e in app.constraints.entries.values() if e.kind != "hole"]
    open_tab(web, "Constraints")
    label = page.get_by_text("plane normal (world)", exact=True)
    row = page.locator("div").filter(has=label).filter(has=page.locator("input")).last
    inputs = row.locator("input")
    expect(inputs).to_have_count(3)
    inputs.nth(1).fill("0")  # (0, 1, 0) -> (0, 0, 0)
    normal = ui.constraint_panel.inputs["plane"]["normal"]
    wait_until(lambda: tuple(normal.value) == (0.0, 0.0, 0.0), WAIT,
               "the plane normal (0, 0, 0) to reach the server")
    applied = ui.inbox.applied
    press(web, "Add plane", ui.constraint_panel.add_buttons["plane"],
          lambda: ui.inbox.applied > applied, "the plane to be refused")
    expect(page.get_by_text("the plane normal must be a non-zero 3-vector").first).to_be_visible()
    expect(page.get_by_text("Not possible", exact=True).first).to_be_visible()
    assert "Traceback" not in page.inner_text("body")
    assert [e for e in app.constraints.entries.values() if e.kind != "hole"] == planes_before
    assert web.control.error is None and web.control.alive
    inputs.nth(1).fill("1")
    wait_until(lambda: tuple(normal.value) == (0.0, 1.0, 0.0), WAIT,
               "the plane normal to be restored")


def test_ghost_from_the_checkbox_draws_its_plot_lines_and_the_readme_screenshot(web, tmp_path):
    app, page, ui = web.app, web.page, web.ui
    ensure_hole(web)
    open_tab(web, "Teleop")
    if app.robots.specs["main"] != "cjm":  # CJM beside the QP
        choose(web, "main", "cjm")
        wait_until(lambda: app.robots.specs["main"] == "cjm", WAIT, "the app to switch to cjm")
    checkbox = page.get_by_label("side by side")
    started = time.perf_counter()
    checkbox.check()
    open_tab(web, "Plots")
    wait_until(lambda: "ghost" in app.robots.loops, WAIT, "the ghost robot")
    # a line per plot, however short (the ghost's history starts now, on a 10 s axis)
    found = wait_for_plot_lines(web, {"ghost": hex_rgb(GHOST_COLOR)}, count=5, since=started,
                                minimum=15)
    assert app.robots.specs["ghost"] == "qp:daqp"
    # the ghost draws over the main robot's line where they agree; the step times differ
    main = uplot_line_pixels(page, hex_rgb(MAIN_COLOR))
    assert main[3] >= 15, (main, found)
    expect(page.get_by_text("joint-velocity deviation", exact=False)).to_be_visible()

    # the nudge buttons move the target by the step, the gizmo following (on the target,
    # none drawn apart); both robots follow, and the plots show how
    open_tab(web, "Teleop")
    target0 = app.console.target.translation.copy()
    for label in ("+y", "+y", "+y", "-z", "-z"):
        before = app.console.target.translation.copy()
        step = 0.005 * np.array(NUDGES[label], dtype=float)
        press(web, label, ui.teleop_panel.nudge_buttons,
              lambda: np.linalg.norm(app.console.target.translation - before - step) < 1e-9,
              f"the target nudged {label}")
    wait_until(lambda: np.linalg.norm(app.console.target.translation - target0 - [0, 0.015, -0.01]) < 1e-9,
               WAIT, "the target nudged by (0, 15, -10) mm")
    wait_until(lambda: np.linalg.norm(np.asarray(web.ui.scene.target_gizmo.position)
                                      - app.console.target.translation) < 1e-6, WAIT,
               "the gizmo on the nudged target")
    np.testing.assert_allclose(app.console.gizmo.translation, app.console.target.translation, atol=1e-12)
    open_tab(web, "Plots")
    time.sleep(2.0)

    # the README's screenshot: the hole, CJM and QP as two robots side by side, the plots
    wait_until(lambda: "ghost" in ui.scene.views, WAIT, "the ghost drawn")
    offset = app.robots.ghost_offset
    model = app.robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, app.robots.loops["main"].q)
    joints = np.array([placement.translation for placement in data.oMi[1:]])
    centre = joints.mean(axis=0) + 0.5 * offset + np.array([0.0, 0.0, -0.05])
    side = offset / np.linalg.norm(offset)  # the ghost's side: the left, seen from the front
    front = np.cross([0.0, 0.0, 1.0], side)
    # the two robots left of the control panel (on the right): look right of their centre
    look = centre - 0.3 * side
    set_camera(web.client, look + 1.3 * front - 0.2 * side + np.array([0.0, 0.0, 0.6]), look)
    close_notifications(page)
    if page.get_by_text("lateness p99", exact=False).is_visible():  # the status line alone
        page.get_by_text("Details", exact=True).click()
    time.sleep(1.0)
    png = page.screenshot(timeout=1e3 * WAIT)
    ARTIFACTS.mkdir(exist_ok=True)
    saved = []
    for path in (ARTIFACTS / "ui.png", tmp_path / "ui.png"):
        path.write_bytes(png)
        saved.append(path)
    for path in saved:
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 50_000
        pixels = png_pixels(data)
        assert pixels.shape == (VIEWPORT["height"], VIEWPORT["width"], 3)
        assert distinct_colours(pixels) > 500
    print(f"\n[browser] screenshot saved to {saved[0]} and {saved[1]}")
    assert web.page_errors == [], web.page_errors
