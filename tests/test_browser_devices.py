"""End to end, an input device in the operator's view: a real Chromium against the real
server, a network master streaming over UDP. The device's +x moves the tool along the
screen's right, and after the view turns 90 degrees about the vertical, along the new
right (docs/design.md section 19.1). Every wait is bounded (tests/browser_helpers.py)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from browser_helpers import WAIT, open_web, set_camera, wait_until, watchdog  # noqa: F401

from teleop import load_robot
from teleop.inputs import DEFAULT_VIEW, MasterClient, UdpMaster

STEP = 0.02  # m of device motion along its x


def screen_right(position, look_at, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """The screen's right in the world for a camera at ``position`` looking at
    ``look_at`` with ``up`` up (viser's default): forward x up, normalised."""
    forward = np.subtract(look_at, position, dtype=float)
    right = np.cross(forward, up)
    return right / np.linalg.norm(right)


class Streamer:
    """A master streaming its current device position at 200 Hz from a thread, so the
    watchdog never releases it between the test's moves."""

    def __init__(self, port: int, key: bytes) -> None:
        self.client = MasterClient(port, key=key)
        self.position = np.zeros(3)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.client.send_pose(tuple(self.position))
            self.client.feedback()
            time.sleep(0.005)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self.client.close()


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    master = UdpMaster(port=0, max_age=1.0)
    # not a test of the watchdog: a stall of the shared process never releases the master
    with open_web(load_robot("sda10f"), tmp_path_factory.mktemp("sessions"),
                  inputs=[master], input_timeout=1.0) as served:
        streamer = Streamer(master.port, master.key)
        try:
            yield served, master, streamer
        finally:
            streamer.close()
            served.app.devices.close()


def move_device_x(console, to: float) -> np.ndarray:
    """Slide the device's x to ``to`` over 0.4 s; the target's displacement, once the
    commands up to the last have been applied."""
    web, master, streamer = console
    before = web.app.console.targets[0].translation.copy()
    start = streamer.position[0]
    for fraction in np.linspace(0.0, 1.0, 81)[1:]:
        streamer.position = np.array([start + fraction * (to - start), 0.0, 0.0])
        time.sleep(0.005)
    sent = streamer.client.sequence
    wait_until(lambda: master.applied_sequence > sent + 2, WAIT, "the last move applied")
    return web.app.console.targets[0].translation - before


def view_of(web, position, look_at) -> np.ndarray:
    """Set the browser's camera, wait until its report has reached the app's mapping, and
    return the screen's right computed here."""
    right = screen_right(position, look_at)
    set_camera(web.client, position, look_at)
    wait_until(lambda: np.allclose(web.app.devices.view_rotation[:, 0], right, atol=1e-3), WAIT,
               f"the app's view to take the browser's camera (right {right})")
    return right


def test_device_x_moves_the_tool_along_the_views_right_and_turns_with_the_view(console):
    web, master, streamer = console
    wait_until(lambda: master.counts["applied"] > 10, WAIT, "the master's first commands")
    assert not np.allclose(web.app.devices.view_rotation, DEFAULT_VIEW)  # a browser has reported
    look_at = web.app.console.targets[0].translation.copy()
    eye = look_at + np.array([1.2, -0.8, 0.5])
    right = view_of(web, eye, look_at)
    first = move_device_x(console, STEP)
    assert np.linalg.norm(first) == pytest.approx(STEP, rel=1e-3)
    assert first / np.linalg.norm(first) @ right > 0.9999, (first, right)

    # the view turned 90 degrees about the vertical, around the point it looks at
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned_right = view_of(web, look_at + quarter @ (eye - look_at), look_at)
    assert turned_right == pytest.approx(quarter @ right, abs=1e-9)
    second = move_device_x(console, 2 * STEP)
    assert np.linalg.norm(second) == pytest.approx(STEP, rel=1e-3)
    assert second / np.linalg.norm(second) @ turned_right > 0.9999, (second, turned_right)
    assert abs(first @ second) / STEP**2 < 1e-2  # perpendicular to the first move
    assert master.dropped() == 0 and web.app.devices[0].state.name == "FOLLOWING"
