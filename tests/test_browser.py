"""End to end: the real `teleop web` server driven by a real (headless) Chromium.

The server runs in-process (``run_server``), the browser is Playwright's Chromium with
software WebGL (SwiftShader), so these tests need no GPU and no display. They check what
an operator sees and does: the page loads and registers as a viser client (viser counts a
browser only once its WebGL view is up), the robot is drawn, a *real mouse drag* of the
target gizmo moves the end effector while a hole holds the link (constraint error
<= 1e-6 m), "Add hole" creates a hole and its ring, the controller menu switches the
controller, an impossible action becomes a notification, and a screenshot is saved.

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

import faulthandler
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import (
    CHROMIUM_ARGS,
    Sampler,
    changed_fraction,
    chromium_executable,
    distinct_colours,
    ee_position,
    free_port,
    png_pixels,
    project,
    scene_canvas,
    set_camera,
    trace_since,
    wait_until,
)
from playwright.sync_api import expect, sync_playwright

from teleop import load_robot
from web.ui import run_server

VIEWPORT = {"width": 1280, "height": 800}
CONNECT_TIMEOUT = 60.0  # s: page load + WebGL start under software rendering
HOLE_TOLERANCE = 1e-6  # m
TEST_HARD_LIMIT = 240.0  # s: see watchdog()
ARTIFACTS = Path(__file__).resolve().parent / "artifacts"


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    """The real server (port picked free) and one Chromium page connected to it."""
    executable = chromium_executable()  # fails (does not skip) when Chromium is missing
    robot = load_robot("sda10f")
    port = free_port()
    server, app, control, ui = run_server(robot, port=port,
                                          record_dir=tmp_path_factory.mktemp("sessions"))
    # Rendering only, for SwiftShader on a small CI machine: with viser's shadow-casting
    # default lights a frame takes ~2 s once the robot moves; the image-based lighting
    # (environment map) makes each frame 2-3 times slower again, and the page handles a
    # drag's pointer moves at the frame rate. The page, scene and app are otherwise exactly
    # what `teleop web` serves.
    server.scene.configure_default_lights(cast_shadow=False)
    server.scene.configure_environment_map(None)
    playwright = browser = None
    page_errors: list[str] = []
    try:
        playwright = sync_playwright().start()
        browser = playwright.chromium.launch(executable_path=executable, headless=True,
                                             args=list(CHROMIUM_ARGS), timeout=60_000)
        page = browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(30_000)
        page.on("pageerror", lambda error: page_errors.append(str(error)))
        started = time.perf_counter()
        response = page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded",
                             timeout=30_000)
        client = wait_until(lambda: next(iter(server.get_clients().values()), None),
                            CONNECT_TIMEOUT, "the browser to register as a viser client "
                            "(its WebGL view must come up)", interval=0.1)
        print(f"\n[browser] client registered {time.perf_counter() - started:.1f} s after "
              "the page was requested")
        wait_for_steady_frames(page)
        yield SimpleNamespace(server=server, app=app, control=control, ui=ui, robot=robot,
                              page=page, client=client, response=response,
                              page_errors=page_errors, hole_time=None)
    finally:
        faulthandler.dump_traceback_later(60.0, exit=True)  # a teardown must not hang either
        try:
            if browser is not None:
                browser.close()
            if playwright is not None:
                playwright.stop()
        finally:
            ui.stop()
            control.stop()
            server.stop()
            faulthandler.cancel_dump_traceback_later()


@pytest.fixture(autouse=True)
def watchdog():
    """Last resort against a wedged browser (Playwright's mouse calls have no timeout): dump
    every thread's stack and end the run if one test takes longer than this."""
    faulthandler.dump_traceback_later(TEST_HARD_LIMIT, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


# -- helpers that act through the page ---------------------------------------------------------

def wait_for_steady_frames(page, timeout: float = 60.0) -> None:
    """Until the page draws frames promptly: the first frames with the robot compile shaders
    (seconds under SwiftShader) and the page answers nothing meanwhile."""
    deadline = time.perf_counter() + timeout
    quick = 0
    while quick < 3:
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            raise AssertionError(f"the page did not settle to steady frames in {timeout:g} s")
        start = time.perf_counter()
        page.wait_for_function("() => true", polling="raf", timeout=1e3 * remaining)
        quick = quick + 1 if time.perf_counter() - start < 0.5 else 0
        time.sleep(0.1)


def holes(app) -> list[str]:
    return [entry_id for entry_id, entry in list(app.entries.items()) if entry.kind == "hole"]


def click_add_hole(web) -> str:
    """Press the page's "Add hole" button; the id of the hole it created."""
    before = set(holes(web.app))
    web.page.get_by_role("button", name="Add hole").click()
    new = wait_until(lambda: set(holes(web.app)) - before, 10.0, "the app to get a new hole")
    (hole_id,) = new
    web.hole_time = web.app.now  # loop time from which the hole is in force
    return hole_id


def ensure_hole(web) -> str:
    existing = holes(web.app)
    return existing[0] if existing else click_add_hole(web)


def canvas_pixels(web) -> np.ndarray:
    box = scene_canvas(web.page)
    png = web.page.screenshot(clip={"x": box.x, "y": box.y, "width": box.width,
                                    "height": box.height}, timeout=30_000)
    return png_pixels(png)


def wait_for_pixels(web, predicate, timeout: float, what: str) -> np.ndarray:
    """Screenshots of the canvas until ``predicate(pixels)`` holds (bounded)."""
    deadline = time.perf_counter() + timeout
    while True:
        pixels = canvas_pixels(web)
        if predicate(pixels):
            return pixels
        if time.perf_counter() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.2)


def look_at_target(web, distance: float = 0.3) -> None:
    """Camera in front of the target gizmo, from the front-right and above."""
    target = web.app.target.translation.copy()
    direction = np.array([0.55, -0.65, 0.45])
    set_camera(web.client, target + distance * direction / np.linalg.norm(direction), target)


def plan_drag(web, distance: float, steps: int, prefer_sign: float = 1.0):
    """Where to grab the target gizmo and how to move the mouse for ``distance`` m.

    Grabs a translation arrow near its tip (88 % of its length: past the rotation arcs at
    65 %), keeps the path on the free part of the canvas (not under the control panel, not
    over the hole's own gizmo) and prefers the arrow that looks longest on screen.
    """
    page, camera = web.page, web.client.camera
    box = scene_canvas(page)
    panel = page.get_by_role("button", name="Add hole").bounding_box()
    panel_left = panel["x"] - 40.0 if panel else box.x + 0.7 * box.width
    right = pin.Quaternion(*camera.wxyz).normalized().matrix()[:, 0]  # camera x, in the world
    avoid = []  # the constraints' own gizmos: circles on screen
    for markers in list(web.ui._markers.values()):
        position, scale = np.asarray(markers["gizmo"].position), markers["gizmo"].scale
        centre, edge = project(camera, box, [position, position + scale * right])
        avoid.append((centre, 1.2 * np.linalg.norm(edge - centre) + 10.0))
    gizmo = web.ui.target_gizmo
    origin = np.asarray(gizmo.position, dtype=float)
    w, x, y, z = gizmo.wxyz
    rotation = pin.Quaternion(w, x, y, z).normalized().matrix()
    best = None
    for axis in range(3):
        for sign in (prefer_sign, -prefer_sign):
            grab = origin + 0.88 * gizmo.scale * rotation[:, axis]
            path = [grab + sign * distance * rotation[:, axis] * k / steps
                    for k in range(steps + 1)]
            screen = project(camera, box, path)
            ok = all(box.x + 0.3 * box.width < p[0] < panel_left  # clear of notifications
                     and box.y + 0.2 * box.height < p[1] < box.y + 0.95 * box.height
                     for p in screen) and all(
                np.linalg.norm(p - c) > r for p in screen for c, r in avoid)
            length = float(np.linalg.norm(screen[-1] - screen[0]))
            if ok and (best is None or length > best[0] * 1.5):
                best = (length, axis, sign, screen)
    assert best is not None, "no arrow of the target gizmo can be grabbed from this camera"
    length, axis, sign, screen = best
    assert length / steps >= 1.0, f"drag steps of {length / steps:.2f} px are too fine"
    return SimpleNamespace(axis=axis, sign=sign, screen=screen, pixels=length,
                           direction=sign * rotation[:, axis], origin=origin)


def drag(web, plan) -> SimpleNamespace:
    """The real mouse: press on the arrow, move step by step, release. Wall times."""
    mouse = web.page.mouse
    mouse.move(*plan.screen[0])
    mouse.down()
    moves, handled = [], []
    for u, v in plan.screen[1:]:
        start = time.perf_counter()
        mouse.move(float(u), float(v))  # returns once the page has handled the event
        moves.append(start)
        handled.append(time.perf_counter() - start)
    up = time.perf_counter()
    mouse.up()
    return SimpleNamespace(moves=moves, handled=np.array(handled), first=moves[0], up=up)


def measured_drag(web, distance: float, steps: int, prefer_sign: float = 1.0):
    """Plan and do a drag of the target gizmo while sampling the server; the measures."""
    app = web.app
    plan = plan_drag(web, distance, steps, prefer_sign)
    target0, ee0 = app.target.translation.copy(), ee_position(app)
    with Sampler(app) as sampler:
        times = drag(web, plan)
        moved = wait_until(
            lambda: np.linalg.norm(app.target.translation - target0) > 0.5 * distance, 5.0,
            "the server-side target to follow the drag (did the mouse grab the gizmo?)")
        target1 = app.target.translation.copy()
        unit = (target1 - target0) / np.linalg.norm(target1 - target0)
        wait_until(lambda: np.linalg.norm(ee_position(app) - app.target.translation) < 1e-4,
                   5.0, "the EE to reach the dragged target")
        settled = time.perf_counter()
        time.sleep(0.2)
    assert moved
    samples = list(sampler.samples)
    target_changed = next(s for s in samples if np.linalg.norm(s.target - target0) > 1e-9)
    ee_moved = next(s for s in samples if (s.ee - ee0) @ unit > 1e-3)
    per_move = []
    for k, start in enumerate(times.moves, start=1):  # when each move reached the server
        expected = distance * k / steps
        hit = next((s for s in samples if s.wall >= start
                    and (s.target - target0) @ unit >= expected - 0.3e-3), None)
        if hit is not None:
            per_move.append(hit.wall - start)
    return SimpleNamespace(
        plan=plan, target0=target0, target1=target1, ee0=ee0, ee1=ee_position(app),
        samples=samples, drag_time=times.up - times.first,
        target_latency=target_changed.wall - times.first,
        ee_latency=ee_moved.wall - times.first,
        per_move=np.array(per_move), handled=times.handled, moves=len(times.moves),
        settle_after_up=settled - times.up,
        max_sampled_error=float(np.nanmax([s.constraint_error for s in samples])))


def report_drag(label: str, result, control) -> None:
    print(f"\n[{label}] drag of {1e3 * np.linalg.norm(result.target1 - result.target0):.1f} mm "
          f"along gizmo axis {result.plan.axis} ({result.plan.pixels:.0f} px, "
          f"{result.moves} mouse moves in {result.drag_time:.2f} s)")
    print(f"[{label}] first mouse move -> server target changed: "
          f"{1e3 * result.target_latency:.0f} ms; -> EE moved 1 mm toward the new target: "
          f"{1e3 * result.ee_latency:.0f} ms")
    print(f"[{label}] the page handles a drag mouse move in: median "
          f"{1e3 * np.median(result.handled):.0f} ms, max {1e3 * result.handled.max():.0f} ms")
    if result.per_move.size:
        print(f"[{label}] each mouse move -> server target ({result.per_move.size} matched): "
              f"median {1e3 * np.median(result.per_move):.0f} ms, "
              f"max {1e3 * result.per_move.max():.0f} ms")
    print(f"[{label}] mouse up -> EE within 0.1 mm of the final target: "
          f"{1e3 * result.settle_after_up:.0f} ms")
    print(f"[{label}] max hole error while dragging: {result.max_sampled_error:.2e} m "
          f"({len(result.samples)} samples)")
    print(f"[{label}] control rate {control.achieved_rate:.0f} Hz achieved (target "
          f"{1.0 / control.app.config.dt:.0f} Hz), {control.deadline_misses} deadline misses")


# -- the tests ---------------------------------------------------------------------------------

def test_page_loads_and_the_browser_registers_as_a_client(web):
    assert web.response is not None and web.response.ok
    assert web.page.title() == "Viser"
    clients = web.server.get_clients()
    assert len(clients) == 1  # registered: viser counts a client once its WebGL view is up
    for folder in ("Controller", "Constraints", "Control", "Record", "Status"):
        expect(web.page.get_by_text(folder, exact=True)).to_be_visible()
    camera = web.client.camera  # the browser reports its camera: the 3D view is running
    box = scene_canvas(web.page)
    assert camera.fov > 0 and (camera.image_width, camera.image_height) == (round(box.width),
                                                                           round(box.height))
    # the view thread publishes the status (control rate) into the page
    expect(web.page.get_by_text("Hz achieved")).to_be_visible(timeout=15_000)
    print(f"\n[browser] control rate with the browser connected: "
          f"{web.control.achieved_rate:.0f} Hz (target {1.0 / web.app.config.dt:.0f} Hz)")


def test_robot_is_in_the_scene(web):
    visualiser = web.ui._visualisers["main"]
    visual = [g.name for g in web.robot.visual_model.geometryObjects]
    assert visual, "the robot has no visual geometry"
    for name in visual:
        handle = visualiser.frames.get(f"/main/visual/{name}")
        assert handle is not None, f"visual {name} is not in the scene"
        assert handle.visible
    assert visualiser.visualRootFrame.visible

    # what the browser draws: not blank, and the robot is a good part of it
    look_at_target(web, distance=1.0)
    shown = wait_for_pixels(web, lambda p: distinct_colours(p) > 100 and p.std() > 10.0, 20.0,
                            "a canvas that is not blank")
    visualiser.displayVisuals(False)
    try:
        hidden = wait_for_pixels(web, lambda p: changed_fraction(p, shown) > 0.01, 20.0,
                                 "the canvas to change when the robot is hidden")
    finally:
        visualiser.displayVisuals(True)
    fraction = changed_fraction(hidden, shown)
    wait_for_pixels(web, lambda p: changed_fraction(p, shown) < 0.25 * fraction, 20.0,
                    "the robot to be drawn again")
    print(f"\n[browser] the robot covers {100 * fraction:.1f} % of the canvas; "
          f"{distinct_colours(shown)} distinct colours")


def test_add_hole_button_creates_a_hole_and_its_ring(web):
    app = web.app
    # look at the constrained link, where the hole will be, to see the ring appear
    robot = web.robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, app.loops["main"].q)
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
    entry = app.entries[hole_id]
    assert entry.kind == "hole"
    assert np.linalg.norm(entry.goal - centre) < 1e-6  # "hole at (m)" = 0.08 on the link axis
    markers = wait_until(lambda: web.ui._markers.get(hole_id), 5.0, "the hole's markers")
    assert markers["shape"].name == f"/constraints/{hole_id}/ring"
    ring = np.asarray(markers["shape"].points)
    assert ring.shape[1:] == (2, 3)
    radius = np.linalg.norm(ring.reshape(-1, 3) - entry.goal, axis=1)
    assert np.allclose(radius, web.ui.ring_radius, atol=1e-6)
    # around the link, not hidden inside it
    link_radius = max(g.geometry.radius for g in robot.visual_model.geometryObjects
                      if g.parentFrame == robot.model.getFrameId(robot.constrained_link)
                      and type(g.geometry).__name__ == "Cylinder")
    assert radius.min() > link_radius
    expect(web.page.get_by_label("placed")).to_have_value(hole_id, timeout=10_000)
    after = wait_for_pixels(web, lambda p: orange(p) > before + 30, 20.0,
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
    np.testing.assert_allclose(web.ui.target_gizmo.position, result.target1, atol=1e-6)
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
    assert app.specs["main"] == "cjm"
    menu = page.get_by_label("main", exact=True)
    menu.click()
    page.get_by_role("option", name="qp:daqp", exact=True).click()
    wait_until(lambda: app.specs["main"] == "qp:daqp", 10.0, "the app to switch to qp:daqp")
    expect(menu).to_have_value("qp:daqp")
    switched = app.now
    assert "qp" in type(app.loops["main"].controller).__name__.lower()
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
    assert trace["constraint_error"].max() <= HOLE_TOLERANCE, trace["constraint_error"].max()
    assert app.last_records["main"] is not None and not app.last_records["main"].failed


def test_impossible_action_shows_a_notification(web):
    app, page, ui = web.app, web.page, web.ui
    planes_before = [e for e in app.entries.values() if e.kind != "hole"]
    label = page.get_by_text("plane normal", exact=True)
    row = page.locator("div").filter(has=label).filter(has=page.locator("input")).last
    inputs = row.locator("input")
    expect(inputs).to_have_count(3)
    inputs.nth(1).fill("0")  # (0, 1, 0) -> (0, 0, 0)
    wait_until(lambda: tuple(ui.plane_normal.value) == (0.0, 0.0, 0.0), 10.0,
               "the plane normal (0, 0, 0) to reach the server")
    page.get_by_role("button", name="Add plane").click()
    expect(page.get_by_text("the plane normal must be a non-zero 3-vector").first).to_be_visible(
        timeout=10_000)
    expect(page.get_by_text("Not possible", exact=True).first).to_be_visible()
    assert "Traceback" not in page.inner_text("body")
    assert [e for e in app.entries.values() if e.kind != "hole"] == planes_before
    assert web.control.error is None and web.control.alive
    inputs.nth(1).fill("1")
    wait_until(lambda: tuple(ui.plane_normal.value) == (0.0, 1.0, 0.0), 10.0,
               "the plane normal to be restored")


def test_screenshot_with_the_hole_and_side_by_side(web, tmp_path):
    app, page = web.app, web.page
    ensure_hole(web)
    # the whole robot, its ghost, the hole's ring and the gizmos, with the panels
    target = app.target.translation
    centre = 0.5 * (target + np.array([0.0, 0.0, 0.3])) + np.array([0.05, 0.0, 0.0])
    set_camera(web.client, centre + np.array([0.5, -0.85, 0.42]), centre)
    alone = canvas_pixels(web)
    checkbox = page.get_by_label("side by side")
    checkbox.check()
    wait_until(lambda: "ghost" in app.loops and "ghost" in web.ui._visualisers, 10.0,
               "the ghost robot")
    expect(checkbox).to_be_checked()
    # the translucent ghost over the robot changes the robot's pixels (a few % of the canvas)
    wait_for_pixels(web, lambda p: changed_fraction(p, alone, threshold=8) > 0.005, 20.0,
                    "the ghost robot to be drawn")
    png = page.screenshot(timeout=30_000)
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
