"""End to end, force control in the page (issue 36's target: "a browser test that sets a
force setpoint and sees the contact arrow"): the real `teleop web --plant mujoco` server
(in process, as tests/test_browser.py runs it) and a real headless Chromium.

Through the page's Force tab: "Place tissue under the tool", the setpoint's z typed in
(1.5 N), "Force control" checked. The simulated tip then presses the tissue at the
setpoint (the tissue's force from stiffness x penetration at the simulated robot's tip);
the arrow the view draws is the contact force, 5 cm per newton, its head on the tip; its
green is in the page's pixels where it projects; the Force tab's words and plot show it.
Every wait is bounded.
"""

from __future__ import annotations


import numpy as np
import pinocchio as pin
from browser_helpers import (  # noqa: F401 (watchdog: an autouse fixture)
    press,
    ARTIFACTS,
    WAIT,
    open_tab,
    open_web,
    project,
    scene_canvas,
    set_camera,
    wait_for_pixels,
    wait_until,
    watchdog,
)
from playwright.sync_api import expect

from teleop import load_robot
from web.ui.force_panel import CONTACT_ARROW_PER_NEWTON, CONTACT_COLOR

SETPOINT = 1.5
#: viser holds the arrow's points as float32
FLOAT32 = 4 * float(np.finfo(np.float32).eps)


def _pressed(app) -> float:
    """The tissue's force on the simulated tip: stiffness x penetration (Pinocchio's
    kinematics of MuJoCo's configuration)."""
    tissue, loop = app.force.tissue, app.robots.loops["main"]
    data = app.robot.model.createData()
    pin.framesForwardKinematics(app.robot.model, data, loop.plant.mj_data.qpos.copy())
    tip = data.oMf[app.robot.ee_frame_id].translation
    return tissue.stiffness * max(0.0, float((tissue.point - tip) @ tissue.normal))


def test_a_setpoint_set_in_the_page_presses_the_tissue_and_the_arrow_shows_it(tmp_path):
    with open_web(load_robot("sda10f"), tmp_path / "sessions", plant="mujoco") as web:
        app, page, ui = web.app, web.page, web.ui
        open_tab(web, "Force")
        press(web, "Place tissue under the tool", ui.force_panel.place,
              lambda: app.force.tissue is not None, "the tissue to be placed")
        label = page.get_by_text("Setpoint (N, tool)", exact=True)
        row = page.locator("div").filter(has=label).filter(has=page.locator("input")).last
        inputs = row.locator("input")
        expect(inputs).to_have_count(3)
        inputs.nth(2).fill(str(SETPOINT))
        wait_until(lambda: app.force.setpoint[2] == SETPOINT, WAIT,
                   "the setpoint to reach the app")
        page.get_by_label("Force control").check()
        wait_until(lambda: app.force.enabled, WAIT, "force control to be on")

        # the tip presses the tissue at the setpoint (2 mm at 1 cm/s, then the force loop)
        wait_until(lambda: abs(_pressed(app) - SETPOINT) < 0.01 * SETPOINT, WAIT,
                   "the tissue to be pressed at the setpoint")
        state = app.view.snapshot(history=False)["force"]
        force = float(np.linalg.norm(state["contact"]))
        print(f"\n[force] pressed at {force:.4f} N (setpoint {SETPOINT} N), stiffness x "
              f"penetration {_pressed(app):.4f} N")
        assert abs(force - SETPOINT) < 0.01 * SETPOINT

        # the arrow the view draws: along the force, 5 cm per newton, its head on the tip
        def drawn_arrow():
            arrow = ui.force_panel.arrow
            if arrow is None or not arrow.visible:
                return None
            points = np.asarray(arrow.points, dtype=float)
            now = app.view.snapshot(history=False)["force"]
            expected = CONTACT_ARROW_PER_NEWTON * now["contact"]
            close = np.allclose(points[0, 1] - points[0, 0], expected, atol=1e-4)
            return (points, now) if close and np.allclose(points[0, 1], now["tip"],
                                                          atol=1e-4) else None

        points, now = wait_until(drawn_arrow, WAIT, "the contact arrow drawn at the tip")
        length = float(np.linalg.norm(points[0, 1] - points[0, 0]))
        assert abs(length - CONTACT_ARROW_PER_NEWTON * SETPOINT) < 0.01 * CONTACT_ARROW_PER_NEWTON \
            * SETPOINT + FLOAT32

        # its green in the page's pixels, where it projects: views around the tip in turn
        # (the robot's links may stand between a camera and the arrow)
        tail, direction = points[0, 0], (points[0, 1] - points[0, 0]) / length
        across = np.cross(direction, [0.0, 0.0, 1.0])
        across /= np.linalg.norm(across)
        views = [sign * across + np.array([0.0, 0.0, up]) for up in (0.3, 1.2)
                 for sign in (1, -1)]
        seen = 0
        for view in views:
            middle = tail + 0.5 * length * direction
            set_camera(web.client, middle + 0.25 * view / np.linalg.norm(view), middle)
            box = scene_canvas(page)
            tail, head = project(web.client.camera, box, points[0]) - (box.x, box.y)
            on_screen = float(np.linalg.norm(head - tail))
            rows, columns = np.mgrid[0:round(box.height), 0:round(box.width)]
            pixel = np.stack([columns + 0.5, rows + 0.5], axis=-1)
            along = np.clip(((pixel - tail) @ (head - tail)) / on_screen ** 2, 0.0, 1.0)
            near = np.linalg.norm(pixel - (tail + along[..., None] * (head - tail)),
                                  axis=-1) < 8.0

            def green_on_arrow(pixels: np.ndarray, near=near) -> int:
                shape = (min(pixels.shape[0], near.shape[0]),
                         min(pixels.shape[1], near.shape[1]))
                hit = np.abs(pixels[:shape[0], :shape[1]]
                             - np.array(CONTACT_COLOR)).max(axis=2) < 40
                return int(np.sum(hit & near[:shape[0], :shape[1]]))

            try:
                after = wait_for_pixels(web, lambda p: green_on_arrow(p) > 0.5 * on_screen,
                                        0.25 * WAIT, "the arrow's green where it projects")
            except AssertionError:
                (tmp_path / f"missed_{len(list(tmp_path.glob('missed_*')))}.png").write_bytes(
                    page.screenshot(timeout=1e3 * WAIT))
                continue
            seen = green_on_arrow(after)
            print(f"[force] the arrow: {on_screen:.0f} px on screen, {seen} green pixels")
            break
        assert seen, f"the contact arrow's green is in no view of {len(views)} around the tip"
        (tmp_path / "ui_force.png").write_bytes(page.screenshot(timeout=1e3 * WAIT))
        ARTIFACTS.mkdir(exist_ok=True)
        (ARTIFACTS / "ui_force.png").write_bytes(page.screenshot(timeout=1e3 * WAIT))

        # the Force tab's words and plot
        expect(page.get_by_text(f"contact force {SETPOINT:.2f}", exact=False).first) \
            .to_be_visible()
        expect(page.get_by_text("contact force on the tool tip (N)", exact=False)) \
            .to_be_visible()
        assert web.control.error is None and web.page_errors == [], web.page_errors
