"""The README's screenshot of collision avoidance: docs/images/collision_dual.png.

``python docs/make_collision_screenshot.py [--out PATH] [--controller SPEC]`` serves `teleop web --robot
sda10f_dual` (in process, on a free loopback port), opens it in headless Chromium
(software WebGL), drives the two tips' targets across each other, waits until the
controller holds the arms apart (the closest pair highlighted, its witness segment drawn)
and saves the 3D view. Chromium: ``/usr/bin/chromium`` or ``$TELEOP_TEST_CHROMIUM``.
"""

from __future__ import annotations

import argparse
import os
import socket
import time
from pathlib import Path

import numpy as np

from teleop import load_robot
from web.ui import run_server

OUT = Path(__file__).resolve().parent / "images" / "collision_dual.png"
CHROMIUM = os.environ.get("TELEOP_TEST_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ("--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--no-first-run")
#: each tip's target goes this far (m) towards and past the other's, along y
CROSSING = 0.16
WAIT = 120.0  # s: any wait (software WebGL on a busy machine)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate, what: str, timeout: float = WAIT):
    deadline = time.monotonic() + timeout
    while not (value := predicate()):
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out waiting for {what}")
        time.sleep(0.1)
    return value


def open_page(playwright, server, port: int, height: int):
    """Headless Chromium (software WebGL) on the page at ``port``, 1400 px wide, once it
    has connected to ``server``: the browser, the page, its viser client."""
    browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                         args=list(CHROMIUM_ARGS))
    page = browser.new_page(viewport={"width": 1400, "height": height})
    page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
    client = wait_until(lambda: next(iter(server.get_clients().values()), None),
                        "the page to connect")
    return browser, page, client


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--controller", default="cjm", help="the page's controller")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    robot = load_robot("sda10f_dual")
    port = free_port()
    scratch = Path("/tmp") / f"collision-screenshot-{port}"
    server, app, control, ui = run_server(robot, port=port, controller=args.controller,
                                          record_dir=scratch / "sessions",
                                          scene_dir=scratch / "scenes")
    server.scene.configure_default_lights(cast_shadow=False)
    try:
        with sync_playwright() as playwright:
            browser, page, client = open_page(playwright, server, port, height=900)
            # the tips point at each other (along y): their targets cross
            for ee, side in ((0, -1.0), (1, 1.0)):
                for _ in range(int(CROSSING / 0.02)):
                    app.console.nudge_target([0.0, 0.02 * side, 0.0], ee)
            ui.scene.move_gizmos()

            def held() -> bool:
                rows = app.collision_rows.get("main")
                before = None if rows is None else rows.minimum_distance
                time.sleep(0.5)
                rows = app.collision_rows.get("main")
                return (rows is not None and rows.size > 0 and before is not None
                        and abs(rows.minimum_distance - before) < 1e-5)

            wait_until(held, "the arms to be held apart")
            rows = app.collision_rows["main"]
            wait_until(lambda: rows.closest_pair in ui.pair_highlights.pair_nodes, "the pair highlighted")
            for handle in (*ui.scene.target_gizmos, *ui.scene.target_markers, *ui.scene.reach_lines):
                handle.visible = False
            for button in page.locator("[class*='Notification'] button").all():
                button.click()  # "software WebGL" and the like
            witness = np.asarray(rows.witnesses[list(rows.pairs).index(rows.closest_pair)])
            middle = witness.mean(axis=0)
            client.camera.position = middle + np.array([0.26, -0.12, 0.20])
            client.camera.look_at = middle + np.array([-0.08, 0.0, 0.02])
            time.sleep(3.0)  # the page draws the new view
            page.wait_for_function("() => true", polling="raf", timeout=1e3 * WAIT)
            panel = page.get_by_role("tab", name="Teleop", exact=True).bounding_box()
            width = (panel["x"] - 20.0) if panel else 1000.0
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out), clip={"x": 0, "y": 0, "width": width,
                                                      "height": 900})
            print(f"{args.out}: {rows.closest_pair} held at "
                  f"{1e3 * rows.minimum_distance:.2f} mm (d_s "
                  f"{1e3 * app.avoidance.safety_distance:g} mm)")
            browser.close()
    finally:
        ui.stop()
        control.stop()
        server.stop()


if __name__ == "__main__":
    main()
