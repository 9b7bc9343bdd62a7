"""Cross-site websocket hijacking, in real Chromium: a page served from another origin
(a small HTTP server on another port of this machine) whose script opens a websocket to
the UI gets nothing, even with the token in its URL, and the robot does not move; the
UI's own origin with the token gets the scene. (Raw clients: tests/test_web_access.py.)"""

from __future__ import annotations

import http.server
import threading
import time

import numpy as np
import pytest
import viser
from browser_helpers import (CHROMIUM_ARGS, WAIT, chromium_executable, ee_position, free_port,
                             wait_until, watchdog)  # noqa: F401 (the watchdog fixture)

from teleop import load_robot
from web.access import make_token

#: a script that opens a websocket to the UI and counts what it receives in 5 s
PROBE = """async ([url, protocol]) => {
    const result = {messages: 0, bytes: 0, opened: false, closed: null};
    await new Promise(done => {
        const ws = new WebSocket(url, [protocol]);
        ws.binaryType = "arraybuffer";
        ws.onopen = () => { result.opened = true; };
        ws.onmessage = (event) => { result.messages += 1; result.bytes += event.data.byteLength; };
        ws.onclose = (event) => { result.closed = event.code; done(); };
        setTimeout(() => { ws.close(); done(); }, 5000);
    });
    return result;
}"""


@pytest.fixture(scope="module")
def ui(tmp_path_factory):
    from web.ui import run_server

    folder = tmp_path_factory.mktemp("origin")
    token = make_token("auto")
    port = free_port()
    server, app, control, view = run_server(load_robot("sda10f"), port=port, rate=250.0,
                                            token=token, record_dir=folder / "sessions",
                                            scene_dir=folder / "scenes")
    try:
        yield server, app, view, token, port
    finally:
        view.stop()
        control.stop()
        server.stop()


@pytest.fixture(scope="module")
def foreign_site(tmp_path_factory):
    """Another origin on this machine: an HTTP server on another port."""
    folder = tmp_path_factory.mktemp("site")
    (folder / "index.html").write_text("<html><body>another site</body></html>")

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, directory=str(folder), **kwargs)

        def log_message(self, *args) -> None:
            pass

    site = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), Quiet)
    thread = threading.Thread(target=site.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{site.server_address[1]}/"
    site.shutdown()
    site.server_close()


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    playwright = sync_playwright().start()
    try:
        chromium = playwright.chromium.launch(executable_path=chromium_executable(),
                                              headless=True, args=list(CHROMIUM_ARGS),
                                              timeout=60_000)
        yield chromium
        chromium.close()
    finally:
        playwright.stop()


def probe(browser, page_address: str, socket_address: str) -> dict:
    page = browser.new_page()
    try:
        page.goto(page_address, wait_until="domcontentloaded", timeout=1e3 * WAIT)
        return page.evaluate(PROBE, [socket_address, f"viser-v{viser.__version__}"])
    finally:
        page.close()


def test_a_page_from_another_origin_gets_nothing_and_moves_nothing(ui, foreign_site, browser):
    server, app, view, token, port = ui
    ee_before, target_before = ee_position(app), app.console.target.translation.copy()
    refused_before = view.access.refused
    for socket_address in (f"ws://127.0.0.1:{port}/?token={token}",  # even with the token
                           f"ws://localhost:{port}/?token={token}", f"ws://127.0.0.1:{port}/"):
        result = probe(browser, foreign_site, socket_address)
        print(f"\n[origin] {foreign_site} -> {socket_address.split('?')[0]}: {result}")
        assert result["messages"] == 0 and result["bytes"] == 0 and not result["opened"], result
    assert view.access.refused - refused_before == 3
    assert len(server.get_clients()) == 0
    moved = np.linalg.norm(ee_position(app) - ee_before)
    print(f"[origin] EE moved {1e3 * moved:.2e} mm")
    assert moved < 1e-9 and np.array_equal(app.console.target.translation, target_before)  # round-off


def test_the_ui_s_own_origin_with_its_token_gets_the_scene(ui, browser):
    server, app, view, token, port = ui
    own = f"http://127.0.0.1:{port}/?websocket=ws://127.0.0.1:{port}/?token=nope"  # a page
    # that stays quiet (its own websocket is refused: a wrong token), so the probe's count
    # is the probe's alone
    refused_before = view.access.refused
    result = probe(browser, own, f"ws://127.0.0.1:{port}/?token={token}")
    print(f"\n[origin] own origin with the token: {result}")
    assert result["opened"] and result["messages"] > 10 and result["bytes"] > 10_000, result
    without = probe(browser, own, f"ws://127.0.0.1:{port}/")
    assert without["messages"] == 0 and not without["opened"], without
    time.sleep(0.5)
    assert view.access.refused - refused_before >= 2  # the quiet pages' and the tokenless
