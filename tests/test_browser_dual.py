"""End to end: ``teleop web --robot sda10f_dual`` in a real headless Chromium.

Two arms, two gizmos. A real mouse drags each gizmo in turn (tests/browser_helpers.py:
``plan_drag`` projects a point of one of its arrows with the browser's own camera): the
dragged EE follows its target and the other stays where it was. Then a hole goes on each
arm through the page ("arm" menu, "Add hole"), each gizmo is dragged again with both
instruments through their trocars (the holes held to 1 um), and the README's screenshot of
the two-arm robot through two trocars is taken (tests/artifacts; the README shows a copy).
Its own module: one browser at a time.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import (  # noqa: F401 (watchdog: an autouse fixture)
    choose,
    close_notifications,
    WAIT,
    VIEWPORT,
    distinct_colours,
    drag,
    holes,
    open_tab,
    open_web,
    plan_drag,
    press,
    png_pixels,
    set_camera,
    wait_until,
    watchdog,
)

from teleop import load_robot

HOLE_TOLERANCE = 1e-6  # m
#: written under tests/artifacts (ignored); docs/images/sda10f_dual_trocars.png is a copy of one
SCREENSHOT = Path(__file__).resolve().parent / "artifacts" / "sda10f_dual_trocars.png"


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    with open_web(load_robot("sda10f_dual"), tmp_path_factory.mktemp("sessions")) as served:
        yield served


def ee_positions(app) -> np.ndarray:
    """Each EE's world position, by forward kinematics of the robot's q."""
    robot = app.robot
    with app._lock:
        q = app.robots.loops["main"].q.copy()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return np.array([data.oMf[frame].translation for frame in robot.ee_frame_ids])


def look_at_tool(web, ee: int) -> None:
    """From 2.5 gizmo sizes in front of EE ``ee``'s target (0.3 m), a little outwards and
    above: its gizmo large on the canvas, the other arm's off to the side."""
    target = web.app.console.targets[ee].translation
    outward = np.sign(target[1]) or 1.0
    direction = np.array([0.75, 0.25 * outward, 0.6])
    distance = 2.5 * web.ui.scene.target_gizmos[ee].scale
    set_camera(web.client, target + distance * direction / np.linalg.norm(direction), target)


def settled(app, periods: int = 200, still: float = 1e-7) -> None:
    """Wait until no EE moves by more than ``still`` (m) over ``periods`` control periods:
    counted in the loop's periods, not the wall clock's, so a loaded machine waits longer."""
    def at_rest() -> bool:
        ticks, before = app.ticker.ticks, ee_positions(app)
        wait_until(lambda: app.ticker.ticks - ticks >= periods, WAIT, f"{periods} control periods")
        return bool(np.max(np.abs(ee_positions(app) - before)) <= still)

    wait_until(at_rest, 4 * WAIT, "the EEs at rest", interval=0.0)


def drag_gizmo(web, ee: int, distance: float, steps: int):
    """A real mouse drag of EE ``ee``'s gizmo; the EE positions before and after, the
    target's displacement and the worst hole error the history saw meanwhile."""
    app = web.app
    look_at_tool(web, ee)
    plan = plan_drag(web, distance, steps, ee=ee)
    settled(app)  # the EEs at rest before (with acceleration limits they take longer)
    targets0, ees0, t0 = app.console.targets, ee_positions(app), app.now
    drag(web, plan)
    wait_until(lambda: np.linalg.norm(app.console.targets[ee].translation
                                      - targets0[ee].translation) > 0.5 * distance, WAIT,
               f"EE {ee}'s target to follow the drag (did the mouse grab its gizmo?)")
    settled(app)  # the robot converges (or settles where the holes let it)
    moved = app.console.targets[ee].translation - targets0[ee].translation
    trace = app.view.snapshot()["robots"]["main"]["trace"]
    errors = trace["constraint_error"][trace["t"] >= t0]
    return targets0, ees0, ee_positions(app), moved, float(np.max(errors, initial=0.0))


def test_dragging_each_gizmo_moves_its_own_ee(web):
    app = web.app
    assert len(web.ui.scene.target_gizmos) == 2
    for ee in (0, 1):
        other = 1 - ee
        targets0, ees0, ees1, moved, _ = drag_gizmo(web, ee, distance=0.02, steps=20)
        assert app.console.targets[other].isApprox(targets0[other], 1e-12), "the other target moved"
        wait_until(lambda: np.linalg.norm(ee_positions(app)[ee] - app.console.targets[ee].translation)
                   < 1e-4, WAIT, f"EE {ee} to reach its dragged target")
        ees1 = ee_positions(app)
        print(f"\n[browser dual] gizmo {ee} dragged {1e3 * np.linalg.norm(moved):.1f} mm: EE {ee} "
              f"moved {1e3 * np.linalg.norm(ees1[ee] - ees0[ee]):.1f} mm, the other "
              f"{1e9 * np.linalg.norm(ees1[other] - ees0[other]):.1f} nm")
        np.testing.assert_allclose(ees1[ee] - ees0[ee], moved, atol=1e-4)
        assert np.linalg.norm(ees1[other] - ees0[other]) < 1e-6
        np.testing.assert_allclose(web.ui.scene.target_gizmos[ee].position,
                                   app.console.targets[ee].translation, atol=1e-6)
    assert web.page_errors == [], web.page_errors


def add_hole_on(web, link: str) -> str:
    """Choose ``link`` in the page's "arm" menu and press "Add hole"; the new hole's id."""
    open_tab(web, "Constraints")
    choose(web, "hole arm", link)
    menu = web.ui.constraint_panel.inputs["hole"]["link"]
    wait_until(lambda: menu.value == link, WAIT, f"the arm menu to read {link}")
    before = set(holes(web.app))
    (hole_id,) = press(web, "Add hole", web.ui.constraint_panel.add_buttons["hole"],
                       lambda: set(holes(web.app)) - before, "a new hole")
    return hole_id


def test_two_trocars_hold_while_each_gizmo_is_dragged_and_the_readme_screenshot(web):
    app, robot = web.app, web.robot
    ids = [add_hole_on(web, link) for link in robot.constrained_links]
    assert [app.constraints.entries[i].constraint.link for i in ids] == list(robot.constrained_links)
    # two trocars leave 11 joint directions for two full poses: the tips' positions only
    # (orientation weight 0, README), so each dragged tip can go all the way
    open_tab(web, "Settings")
    # the settings' only slider that ends at 1 (gain: 500, damping: 0.2)
    web.page.locator('[role="slider"][aria-valuemax="1"]').focus()
    web.page.keyboard.press("Home")  # the keyboard's way to a slider's minimum
    wait_until(lambda: app.robots.orientation_weight == 0.0, WAIT, "the orientation weight to be 0")
    open_tab(web, "Teleop")
    for ee in (0, 1):
        _, ees0, ees1, moved, worst = drag_gizmo(web, ee, distance=0.01, steps=10)
        along = float((ees1[ee] - ees0[ee]) @ moved / (moved @ moved))
        other = float(np.linalg.norm(ees1[1 - ee] - ees0[1 - ee]))
        print(f"\n[browser dual] two trocars, gizmo {ee} dragged {1e3 * np.linalg.norm(moved):.1f} mm:"
              f" EE {ee} went {100 * along:.0f} % of the way, the other EE moved "
              f"{1e6 * other:.2f} um; worst hole error {worst:.2e} m")
        assert worst <= HOLE_TOLERANCE
        assert along > 0.95 and other < 1e-5
    assert app.robots.last_records["main"].constraint_error <= HOLE_TOLERANCE

    # the README's screenshot: the robot, both instruments, both rings
    rings = np.array([app.constraints.entries[i].position for i in ids])
    centre = 0.5 * (rings.mean(axis=0) + ee_positions(app).mean(axis=0)) + [-0.05, 0.0, 0.05]
    set_camera(web.client, centre + np.array([0.8, -0.45, 0.5]), centre)
    close_notifications(web.page)
    time.sleep(1.5)
    png = web.page.screenshot(timeout=1e3 * WAIT)
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    SCREENSHOT.write_bytes(png)
    pixels = png_pixels(png)
    assert pixels.shape == (VIEWPORT["height"], VIEWPORT["width"], 3)
    assert distinct_colours(pixels) > 500
    print(f"\n[browser dual] screenshot saved to {SCREENSHOT}")
    assert web.page_errors == [], web.page_errors
