"""The status panel's warning of a control loop falling behind (web/ui/status_view.py): the
banner while it lasts, a notification when it starts, at most one a minute."""

from __future__ import annotations

import pytest
import viser
from browser_helpers import free_port

from teleop import load_robot
from web.app import ControlThread, TeleopApp
from web.ui import status_view


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server
    server.stop()


def test_a_loop_falling_behind_again_and_again_raises_one_notification_a_minute(server, tmp_path,
                                                                               monkeypatch):
    app = TeleopApp(load_robot("sda10f"), controller="cjm", record_dir=tmp_path)
    control = ControlThread(app)
    notices: list[tuple[str, str]] = []
    panel = status_view.StatusPanel(server.gui, control, {"tool0": "main"},
                                    port_peak=lambda: None, device_lines=lambda snapshot: [],
                                    notify=lambda event, title, body, color: notices.append(
                                        (title, body)))
    behind = "control loop behind: only 900 of the 1000 Hz asked for (90 %)"
    # (time in s, the loop behind?): it falls behind, recovers, falls behind 2 s later
    # (no second notification: the banner is up again), then 61 s after the first
    for now, late in ((0.0, True), (1.0, False), (2.0, True), (30.0, False), (59.9, True),
                      (60.5, False), (61.0, True), (62.0, True)):
        monkeypatch.setattr(status_view.time, "monotonic", lambda now=now: now)
        monkeypatch.setattr(control, "behind", lambda late=late: behind if late else "")
        panel.draw(app.view.snapshot())
        assert panel.banner.visible == late, now
        if late:
            assert behind in panel.banner.content
    assert notices == [("Control loop behind", behind)] * 2
