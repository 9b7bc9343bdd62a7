"""End to end, what a page may touch: a real Chromium against ``teleop web --token``.

The page opened at the address the server prints (with its token) works; a page opened
without the token gets nothing and never becomes a client. In the Settings tab, a scene
name that leads out of the scene folder (``../x.json``, an absolute path, a symlinked
folder) is refused with a notification, and nothing is written outside the folder. Its own
module: one browser at a time.
"""

from __future__ import annotations

import os
import time

import pytest
from browser_helpers import (  # noqa: F401 (watchdog: an autouse fixture)
    WAIT,
    input_of,
    open_tab,
    open_web,
    press,
    wait_until,
    watchdog,
)
from playwright.sync_api import TimeoutError as PlaywrightTimeoutError
from playwright.sync_api import expect

from teleop import load_robot

TOKEN = "a-token-for-the-browser-test"


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    root = tmp_path_factory.mktemp("files")
    with open_web(load_robot("sda10f"), root / "recordings", token=TOKEN,
                  scene_dir=root / "scenes") as served:
        served.root = root
        yield served


def files_under(folder) -> set[str]:
    return {os.path.relpath(os.path.join(where, name), folder)
            for where, _, names in os.walk(folder) for name in names}


def test_the_page_at_the_printed_address_works_and_one_without_the_token_gets_nothing(web):
    assert f"?token={TOKEN}" in web.url and len(web.server.get_clients()) == 1
    stranger = web.browser.new_page()
    try:
        stranger.goto(web.url.split("?")[0], wait_until="domcontentloaded", timeout=1e3 * WAIT)
        time.sleep(10.0)  # long enough for a page to come up and register (it never will)
        assert len(web.server.get_clients()) == 1
        assert stranger.get_by_role("tab", name="Settings", exact=True).count() == 0
    finally:
        stranger.close()


def save_scene(web) -> None:
    """Press "Save scene" until the server has acted on it (``press``: a click lost on a
    starved page is told apart from a save that did nothing)."""
    applied = web.ui.inbox.applied
    press(web, "Save scene", web.ui.settings_panel.save_scene_button,
          lambda: web.ui.inbox.applied > applied, "the save to be done or refused")


def test_scene_names_leading_out_of_the_scene_folder_are_refused(web):
    app, page, root = web.app, web.page, web.root
    outside = root / "outside"
    outside.mkdir()
    app.scene_dir.mkdir(parents=True, exist_ok=True)
    (app.scene_dir / "linked.json").symlink_to(outside, target_is_directory=True)
    (app.scene_dir / "linked").symlink_to(outside, target_is_directory=True)
    before = files_under(root)
    open_tab(web, "Settings")
    names = ["../x.json", str(outside / "x.json"), "linked/x.json", "linked.json"]
    for name in names:
        input_of(page, "scene name").fill(name)
        wait_until(lambda: web.ui.settings_panel.scene_path.value == name, WAIT, f"the scene name {name}")
        save_scene(web)
        expect(page.get_by_text(f"scene name {name!r} refused", exact=False).first).to_be_visible()
        for close in page.locator(".mantine-Notification-closeButton").all():
            try:  # housekeeping: a notification may close itself (or move) meanwhile
                close.click(timeout=2000)
            except PlaywrightTimeoutError:
                pass
    assert web.ui.inbox.drain(WAIT)
    assert files_under(root) == before, files_under(root) - before  # nothing written anywhere
    assert "Traceback" not in page.inner_text("body")
    input_of(page, "scene name").fill("inside.json")  # and a plain name is saved inside
    wait_until(lambda: web.ui.settings_panel.scene_path.value == "inside.json", WAIT, "the scene name")
    save_scene(web)
    wait_until((app.scene_dir / "inside.json").is_file, WAIT, "the scene file")
    assert files_under(root) - before == {"scenes/inside.json"}
    assert web.page_errors == [], web.page_errors
