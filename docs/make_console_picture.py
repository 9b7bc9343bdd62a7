"""The README's picture of the console with a network master: docs/images/console_feedback.png.

``python docs/make_console_picture.py [--out PATH] [--plant mujoco]`` serves `teleop web
--rate 500 --input udp:PORT` (in process, on free loopback ports; 500 Hz: software WebGL
takes most of a 2-core machine) with a hole on link 6, streams 1.5 cm circles from a
master process (``teleop.inputs.MasterClient``, 500 Hz) for a few seconds, opens the
page in headless Chromium (software WebGL) on the Plots tab, where the feedback force the
master receives is plotted, and saves the page. Chromium: ``/usr/bin/chromium`` or
``$TELEOP_TEST_CHROMIUM``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from make_collision_screenshot import free_port, open_page

from teleop import load_robot
from teleop.inputs import UdpMaster
from web.ui import run_server

OUT = Path(__file__).resolve().parent / "images" / "console_feedback.png"
RADIUS, PERIOD, RATE = 0.015, 5.0, 500.0


#: the master, a process of its own: circles in the plane of the operator's view, at 1 kHz
MASTER = f"""
import math, sys, time
from teleop.inputs import MasterClient
client = MasterClient(int(sys.argv[1]), sys.argv[2])  # the port and the receiver's key (hex)
start, k = time.perf_counter(), 0
while True:
    angle = 2.0 * math.pi * k / ({RATE} * {PERIOD})
    client.send_pose(({RADIUS} * (math.cos(angle) - 1.0), {RADIUS} * math.sin(angle), 0.0))
    client.feedback()
    k += 1
    time.sleep(max(0.0, start + k / {RATE} - time.perf_counter()))
"""


def close_notifications(page) -> None:
    """Close the page's toasts (software WebGL, ...), as an operator would; one that
    closes by itself meanwhile is fine."""
    from playwright.sync_api import Error as PlaywrightError

    for button in page.locator("[class*='Notification'] button").all():
        try:
            button.click(timeout=2000)
        except PlaywrightError:
            pass
    time.sleep(1.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--plant", default="kinematic", choices=("kinematic", "mujoco"))
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    port = free_port()
    scratch = Path("/tmp") / f"console-picture-{port}"
    master = UdpMaster(port=0)
    server, app, control, ui = run_server(load_robot("sda10f"), port=port, plant=args.plant, rate=RATE,
                                          record_dir=scratch / "sessions",
                                          scene_dir=scratch / "scenes", inputs=[master])
    server.scene.configure_default_lights(cast_shadow=False)
    app.constraints.add("hole", distance=0.08)
    master_process = None
    try:
        with sync_playwright() as playwright:
            browser, page, client = open_page(playwright, server, port, height=1000)
            target = app.console.targets[0].translation
            # from behind-left: the circle in this view keeps the arm away from the
            # singularity a front-right view drives it into
            client.camera.position = target + [-0.95, 1.0, 0.5]
            client.camera.look_at = target + [-0.3, 0.0, -0.15]
            time.sleep(2.0)  # the browser reports its view: the master moves in it
            master_process = subprocess.Popen([sys.executable, "-c", MASTER, str(master.port),
                                               master.key.hex()])
            close_notifications(page)
            page.get_by_role("tab", name="Plots", exact=True).click()
            time.sleep(9.0)  # two circles and more in the plots
            close_notifications(page)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            stats = master.statistics()
            print(f"{args.out}: {stats['received']} commands, latency p99 "
                  f"{stats['latency_p99_ms']:.2f} ms")
            browser.close()
    finally:
        if master_process is not None:
            master_process.kill()
            master_process.wait(10)
        ui.stop()
        control.stop()
        app.devices.close()
        server.stop()


if __name__ == "__main__":
    main()
