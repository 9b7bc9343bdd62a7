"""Helpers for the end-to-end browser tests (tests/test_browser.py).

Everything here is bounded in time: a wait that does not come true raises
``AssertionError`` with what it was waiting for, it never hangs.

Projection: viser reports each client's camera in the OpenCV convention
(``P_world = R p_camera + t``, the camera looks along +z, image y points down, ``fov``
vertical). A world point therefore lands on the canvas at
``cx + f x / z, cy + f y / z`` with ``f = (h / 2) / tan(fov / 2)`` (CSS pixels).
"""

from __future__ import annotations

import contextlib
import faulthandler
import io
import math
import os
import shutil
import signal
import socket
import threading
import warnings
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
import viser
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from playwright.sync_api import expect

#: seconds any wait for the page or the server may take: generous, for a slow loaded
#: machine (software WebGL on 2 shared cores); a wait returns as soon as its condition holds
WAIT = 60.0
expect.set_options(timeout=1e3 * WAIT)

#: where the browser tests leave what they saw (screenshots; kept out of git)
ARTIFACTS = Path(__file__).resolve().parent / "artifacts"

CHROMIUM = os.environ.get("TELEOP_TEST_CHROMIUM", "/usr/bin/chromium")
#: software WebGL (SwiftShader) in a headless, sandbox-less, quiet Chromium
CHROMIUM_ARGS = ("--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync")


def chromium_executable() -> str:
    """The Chromium binary; a clear failure (not a skip) when it is missing."""
    path = CHROMIUM if os.path.isfile(CHROMIUM) else shutil.which("chromium")
    if not path:
        raise AssertionError(
            f"Chromium not found at {CHROMIUM} (nor on PATH): the browser tests need it. "
            "Install it (Debian/Ubuntu: `apt-get install chromium`) or point "
            "TELEOP_TEST_CHROMIUM at a Chromium binary.")
    return path


#: example-robot-data's Panda, installed beside Pinocchio by the ``example-robot-data`` wheel
PANDA = Path(pin.__file__).resolve().parents[4] / "share/example-robot-data/robots/" \
    "panda_description/urdf/panda.urdf"


def answer_ctrl_c() -> None:
    """A child's ``preexec_fn``: SIGINT, SIGTERM and SIGHUP at their defaults, so the
    child answers them as the tests send them even when this test run was started with
    one ignored (SIGINT for a background job of a shell without job control, SIGHUP under
    ``nohup``), which its children would inherit and keep ignoring."""
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)


def close_notifications(page) -> None:
    """Close the page's notifications (e.g. the WebGL notice); one that closes itself
    meanwhile is skipped (CI saw a click wait 60 s for a notification already gone)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    for close in page.locator(".mantine-Notification-closeButton").all():
        try:
            close.click(timeout=2000)
        except PlaywrightTimeoutError:
            pass


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate: Callable[[], object], timeout: float, what: str,
               interval: float = 0.02):
    """Poll ``predicate`` until it returns something truthy (returned); bounded."""
    deadline = time.perf_counter() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.perf_counter() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


# -- camera and canvas ---------------------------------------------------------------------

@dataclass(frozen=True)
class CanvasBox:
    """The 3D canvas in CSS pixels (page coordinates)."""

    x: float
    y: float
    width: float
    height: float


def scene_canvas(page) -> CanvasBox:
    """Bounding box of the largest canvas of the page: viser's WebGL view (the others are plots)."""
    boxes = page.evaluate("""() => Array.from(document.querySelectorAll('canvas'))
        .map(c => c.getBoundingClientRect())
        .map(r => [r.x, r.y, r.width, r.height])""")
    x, y, w, h = max(boxes, key=lambda b: b[2] * b[3])
    assert w > 100 and h > 100, f"no 3D canvas in the page (canvases: {boxes})"
    return CanvasBox(x, y, w, h)


def project(camera, box: CanvasBox, points) -> np.ndarray:
    """Page (CSS pixel) coordinates of world points seen by a viser client camera."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    w, x, y, z = camera.wxyz
    rotation = pin.Quaternion(w, x, y, z).normalized().matrix()  # world <- camera
    in_camera = (points - np.asarray(camera.position)) @ rotation
    if np.any(in_camera[:, 2] <= 1e-6):
        raise AssertionError(f"point behind the camera: {points[in_camera[:, 2] <= 1e-6]}")
    focal = 0.5 * box.height / math.tan(0.5 * camera.fov)
    u = box.x + 0.5 * box.width + focal * in_camera[:, 0] / in_camera[:, 2]
    v = box.y + 0.5 * box.height + focal * in_camera[:, 1] / in_camera[:, 2]
    return np.stack([u, v], axis=1)


#: per client handle (by identity: client ids restart at 0 on every server), the handle
#: itself (so its id is not reused) and the camera poses its browser reported
_ECHOES: dict[int, tuple[object, list[tuple[np.ndarray, np.ndarray]]]] = {}


def _camera_echoes(client) -> list[tuple[np.ndarray, np.ndarray]]:
    """Camera poses (position, look at) the browser of ``client`` reported, in order."""
    if id(client) not in _ECHOES:
        echoes: list[tuple[np.ndarray, np.ndarray]] = []
        _ECHOES[id(client)] = (client, echoes)
        client.camera.on_update(
            lambda camera: echoes.append((camera.position.copy(), camera.look_at.copy())))
    return _ECHOES[id(client)][1]


def set_camera(client, position, look_at, timeout: float = WAIT) -> None:
    """Put a client's camera at a known pose and wait until the browser reports it back.

    The server-side camera state is written by the setters themselves, so it says nothing
    about the browser: wait for a camera message from the browser (``on_update``) with the
    new pose; :func:`project` then uses what the browser really renders (its fov too).
    """
    position = np.asarray(position, dtype=float)
    look_at = np.asarray(look_at, dtype=float)
    echoes = _camera_echoes(client)
    echoes.clear()
    camera = client.camera
    if np.allclose(camera.position, position, atol=1e-3):  # a no-op would not be echoed
        camera.position = position + np.array([0.0, 0.0, 0.05])
    camera.position = position
    camera.look_at = look_at

    def reported() -> bool:
        return any(np.allclose(p, position, atol=1e-3) and np.allclose(a, look_at, atol=1e-3)
                   for p, a in list(echoes))

    wait_until(reported, timeout, f"the browser to report the camera pose {position} -> {look_at}")
    time.sleep(0.3)  # let any late message land, then check the browser still agrees
    state = client.camera
    assert np.allclose(state.position, position, atol=1e-3) and np.allclose(
        state.look_at, look_at, atol=1e-3), "the browser moved the camera after it was set"


# -- images ------------------------------------------------------------------------------

def png_pixels(png: bytes) -> np.ndarray:
    from PIL import Image  # matplotlib depends on Pillow

    with Image.open(io.BytesIO(png)) as image:
        return np.asarray(image.convert("RGB"), dtype=np.int16)


def distinct_colours(pixels: np.ndarray) -> int:
    flat = pixels.reshape(-1, 3).astype(np.int64)
    return int(np.unique(flat[:, 0] << 16 | flat[:, 1] << 8 | flat[:, 2]).size)


def changed_fraction(a: np.ndarray, b: np.ndarray, threshold: int = 24) -> float:
    """Fraction of pixels whose colour differs by more than ``threshold`` (any channel)."""
    return float(np.mean(np.abs(a - b).max(axis=2) > threshold))


# -- the server side -----------------------------------------------------------------------

def ee_position(app) -> np.ndarray:
    """World position of the main robot's EE frame, by forward kinematics of its q."""
    robot = app.robot
    with app._lock:  # a consistent q: a controller switch replaces the loop
        q = app.robots.loops["main"].q.copy()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(robot.ee_frame)].translation.copy()


def trace_since(app, t0: float) -> dict[str, np.ndarray]:
    """The main robot's plotted history (50 samples/s) from loop time ``t0`` on."""
    trace = app.view.snapshot()["robots"]["main"]["trace"]
    keep = trace["t"] >= t0
    return {key: value[keep] for key, value in trace.items()}


@dataclass
class Sample:
    wall: float  # time.perf_counter()
    target: np.ndarray
    ee: np.ndarray
    constraint_error: float
    t: float = math.nan  # the last record's loop time (s)
    status: str = ""  # the last record's status and the controller's own


@dataclass
class Sampler:
    """Samples the server (target, EE position, last tick's constraint error) on a thread."""

    app: object
    period: float = 0.004
    samples: list[Sample] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sampler", daemon=True)

    def _run(self) -> None:
        app = self.app
        while not self._stop.is_set():
            record = app.robots.last_records.get("main")
            error = math.nan if record is None else max(record.constraint_error,
                                                        record.barrier_penetration)
            self.samples.append(Sample(
                time.perf_counter(), app.console.target.translation.copy(), ee_position(app),
                error, math.nan if record is None else record.t,
                "" if record is None else f"{record.status}/{record.controller_status}"))
            time.sleep(self.period)

    def __enter__(self) -> "Sampler":
        self._thread.start()
        wait_until(lambda: self.samples, WAIT, "the first sample")
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def first(self, predicate: Callable[[Sample], bool]) -> Sample | None:
        return next((s for s in list(self.samples) if predicate(s)), None)


# -- a served page ------------------------------------------------------------------------

VIEWPORT = {"width": 1280, "height": 800}
CONNECT_TIMEOUT = 180.0  # s: page load + WebGL start under software rendering
TEST_HARD_LIMIT = 900.0  # s: see watchdog()


@pytest.fixture(autouse=True)
def watchdog():
    """Last resort against a wedged browser (Playwright's mouse calls have no timeout): dump
    every thread's stack and end the run if one test takes longer than this. (Import it into
    a test module to use it there.)"""
    faulthandler.dump_traceback_later(TEST_HARD_LIMIT, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


@contextlib.contextmanager
def open_web(robot, record_dir, token: str | None = "auto", **server_options):
    """The real server (``run_server``, port picked free) and one Chromium page connected
    to it (at the address ``teleop web`` prints: with ``token``, random by default as
    ``teleop web``'s, the page presents it): a namespace with server, app, control, ui,
    robot, page, client, response, page_errors, hole_time, url."""
    from playwright.sync_api import sync_playwright

    from web.access import make_token
    from web.ui import run_server

    executable = chromium_executable()  # fails (does not skip) when Chromium is missing
    server_options.setdefault("scene_dir", Path(record_dir) / "scenes")
    token = None if token is None else make_token(token)
    port = free_port()
    server, app, control, ui = run_server(robot, port=port, record_dir=record_dir,
                                          token=token, **server_options)
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
        page.set_default_timeout(1e3 * WAIT)
        page.on("pageerror", lambda error: page_errors.append(str(error)))
        started = time.perf_counter()
        from web.access import page_url

        url = page_url("127.0.0.1", port, token)
        response = page.goto(url, wait_until="domcontentloaded", timeout=1e3 * WAIT)
        client = wait_until(lambda: next(iter(server.get_clients().values()), None),
                            CONNECT_TIMEOUT, "the browser to register as a viser client "
                            "(its WebGL view must come up)", interval=0.1)
        print(f"\n[browser] client registered {time.perf_counter() - started:.1f} s after "
              "the page was requested")
        wait_for_steady_frames(page)
        yield SimpleNamespace(server=server, app=app, control=control, ui=ui, robot=robot,
                              page=page, client=client, response=response,
                              page_errors=page_errors, hole_time=None, url=url,
                              browser=browser)
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


# -- helpers that act through the page ---------------------------------------------------------


def open_tab(web, name: str) -> None:
    """Show one tab of the control panel (Teleop, Constraints, Settings, Plots), selected
    from the keyboard (the tab focused, Enter), which viser's tab strip offers beside the
    mouse. A press of the mouse on a tab arms the strip's drag gesture (a move of 3 px
    before the release reorders the tabs, the pressed tab following the pointer): on a
    page starved by software rendering, a click left the Plots tab following the pointer
    over the Teleop tab, and every later click there hit the Plots tab for 60 s."""
    tab = web.page.get_by_role("tab", name=name, exact=True)
    tab.press("Enter")
    expect(tab).to_have_attribute("aria-selected", "true")


def choose(web, label: str, option: str) -> None:
    """Choose ``option`` in the page's menu ``label`` (viser's dropdown, a searchable
    select) from the keyboard, as :func:`open_tab` does tabs: its name typed, which leaves
    the options that contain it, then Arrow Down to the one named exactly and Enter. The
    page then shows it (the server's side is the caller's to wait for)."""
    menu = web.page.get_by_label(label, exact=True)
    if menu.input_value() == option:
        return
    menu.fill(option)
    listed = web.page.get_by_role("option")
    expect(web.page.get_by_role("option", name=option, exact=True)).to_be_visible()
    for _ in range(listed.count()):
        menu.press("ArrowDown")
        highlighted = web.page.locator("[data-combobox-selected]")
        expect(highlighted).to_have_count(1)
        if highlighted.inner_text() == option:
            break
    else:
        raise AssertionError(f"{option!r} is not among the options of the menu {label!r}")
    menu.press("Enter")
    expect(menu).to_have_value(option)


def open_status_details(web) -> None:
    """Open the status's "Details" folder (closed by default: the status line shows a
    few plain words), where the control rate, the controller's words and the collision
    pairs are; a no-op when it is open."""
    details = web.page.get_by_text("lateness p99", exact=False)
    if not details.is_visible():
        web.page.get_by_text("Details", exact=True).click()
    expect(details).to_be_visible()


#: counts, in the page, the clicks the document sees on each button (by its id, the
#: uuid viser gives the button's handle), in the capture phase: before any handler
_COUNT_CLICKS = """() => {
    if (window.__teleopClicks) return;
    window.__teleopClicks = {};
    document.addEventListener('click', event => {
        const button = event.target.closest('button');
        if (button && button.id)
            window.__teleopClicks[button.id] = (window.__teleopClicks[button.id] || 0) + 1;
    }, true);
}"""


class LostClick(UserWarning):
    """A click the page sent and the server never got, clicked once more by :func:`press`:
    shown in the run's warnings summary, so that a green run still says it happened."""


def press(web, name: str, handle: viser.GuiButtonHandle, effect: Callable[[], object],
          what: str):
    """Click the page's button ``name`` (whose server-side handle is ``handle``) and
    return ``effect()``'s first true value (``what`` it waits for).

    A click is a message from the page to the server, which stamps the button's handle
    when it handles one (``handle.update_timestamp``): a click the server got and whose
    effect does not come is the app's failure, said so. A click the server did not get
    in :data:`WAIT` s was lost between the page and the server: the failure says whether
    the page saw the click and whether the page is still the server's client, and the
    button is clicked once more (the click provably not delivered, the effect cannot
    have come twice), with a :class:`LostClick` warning; a second loss fails.
    """
    page = web.page
    button = page.get_by_role("button", name=name, exact=True)
    expect(button).to_be_enabled()
    page.evaluate(_COUNT_CLICKS)
    element_id = button.get_attribute("id")
    for attempt in (1, 2):
        stamp = handle.update_timestamp
        seen = page.evaluate("id => window.__teleopClicks[id] || 0", element_id)
        button.click()
        try:
            wait_until(lambda: handle.update_timestamp != stamp, WAIT,
                       f"the server to get the click on {name!r}")
        except AssertionError:
            clicks = page.evaluate("id => window.__teleopClicks[id] || 0", element_id)
            connected = web.client.client_id in web.server.get_clients()
            where = (f"the page saw {clicks - seen} click(s) on it; the page is "
                     f"{'still' if connected else 'no longer'} the server's client "
                     f"{web.client.client_id} (clients: {list(web.server.get_clients())})")
            if attempt == 2:
                raise AssertionError(f"the click on {name!r} never reached the server, "
                                     f"twice ({where})") from None
            warnings.warn(f"the click on {name!r} never reached the server in {WAIT:g} s "
                          f"({where}); clicking once more", LostClick, stacklevel=2)
            continue
        try:
            return wait_until(effect, WAIT, what)
        except AssertionError as error:
            raise AssertionError(f"{error} (viser got the click on {name!r} and stamped its "
                                 f"handle: the app did not act on it; inbox: "
                                 f"{web.ui.inbox.applied} applied, {web.ui.inbox.refused} "
                                 "refused)") from None


def input_of(page, label: str):
    """The (first) input of the panel row labelled ``label``."""
    text = page.get_by_text(label, exact=True)
    row = page.locator("div").filter(has=text).filter(has=page.locator("input")).last
    return row.locator("input").first


def uplot_line_pixels(page, rgb: tuple[int, int, int], tolerance: int = 40) -> list[int]:
    """For each uPlot chart in the page: how many pixels of its canvas have the colour
    ``rgb`` (a series' stroke), read from the canvas itself."""
    return page.evaluate("""([r, g, b, tol]) => Array.from(document.querySelectorAll('.uplot canvas'))
        .map(canvas => {
            const { width, height } = canvas;
            if (!width || !height) return 0;
            const data = canvas.getContext('2d').getImageData(0, 0, width, height).data;
            let count = 0;
            for (let i = 0; i < data.length; i += 4)
                if (data[i + 3] > 0 && Math.abs(data[i] - r) <= tol
                    && Math.abs(data[i + 1] - g) <= tol && Math.abs(data[i + 2] - b) <= tol)
                    count++;
            return count;
        })""", [*rgb, tolerance])


def hex_rgb(color: str) -> tuple[int, int, int]:
    return tuple(int(color[i:i + 2], 16) for i in (1, 3, 5))


#: a frame drawn within this many seconds counts as steady (shader compiles take several)
STEADY_FRAME = 1.5


def wait_for_steady_frames(page, timeout: float = 3.0 * WAIT) -> None:
    """Until the page draws frames promptly: the first frames with the robot compile shaders
    (seconds under SwiftShader) and the page answers nothing meanwhile."""
    deadline = time.perf_counter() + timeout
    quick = 0
    while quick < 3:
        if time.perf_counter() > deadline:
            raise AssertionError(f"the page did not settle to steady frames in {timeout:g} s")
        start = time.perf_counter()
        try:  # one frame, however slow (each wait bounded on its own, never a sliver)
            page.wait_for_function("() => true", polling="raf", timeout=1e3 * WAIT)
        except PlaywrightTimeout:
            quick = 0
            continue
        quick = quick + 1 if time.perf_counter() - start < STEADY_FRAME else 0
        time.sleep(0.1)


def holes(app) -> list[str]:
    return [entry_id for entry_id, entry in list(app.constraints.entries.items()) if entry.kind == "hole"]


def click_add_hole(web) -> str:
    """Press the page's "Add hole" button; the id of the hole it created."""
    before = set(holes(web.app))
    open_tab(web, "Constraints")
    new = press(web, "Add hole", web.ui.constraint_panel.add_buttons["hole"],
                lambda: set(holes(web.app)) - before, "the app to get a new hole")
    (hole_id,) = new
    web.hole_time = web.app.now  # loop time from which the hole is in force
    return hole_id


def ensure_hole(web) -> str:
    existing = holes(web.app)
    return existing[0] if existing else click_add_hole(web)


#: what a screenshot of the 3D view paints over in black: the control panel and the
#: notifications, the page's own, whose text changes on its own (the status line each
#: second on a loaded machine, a notification coming: a still scene never looked still)
OVER_THE_SCENE = ("[data-floating-window]", ".mantine-Notification-root")


def canvas_pixels(web) -> np.ndarray:
    """What the 3D view draws: a screenshot of its canvas, the page's panel and
    notifications over it painted black (:data:`OVER_THE_SCENE`)."""
    page = web.page
    box = scene_canvas(page)
    png = page.screenshot(clip={"x": box.x, "y": box.y, "width": box.width,
                                "height": box.height}, timeout=1e3 * WAIT,
                          mask=[page.locator(selector) for selector in OVER_THE_SCENE],
                          mask_color="#000000")
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


#: two screenshots 0.5 s apart that differ on less than this fraction of the canvas: still
STILL = 1e-3


def wait_for_still_canvas(web, timeout: float) -> np.ndarray:
    """The canvas once two screenshots 0.5 s apart agree (camera and scene settled): a
    reference image taken while the camera still moves would never be seen again."""
    deadline = time.perf_counter() + timeout
    previous = canvas_pixels(web)
    while True:
        time.sleep(0.5)
        pixels = canvas_pixels(web)
        if changed_fraction(pixels, previous) < STILL:
            return pixels
        if time.perf_counter() > deadline:
            raise AssertionError(f"the canvas did not hold still within {timeout:g} s: "
                                 f"{still_failure(previous, pixels)}")
        previous = pixels


def record_failed_page(web, name: str) -> str:
    """A screenshot of the whole page and its text, saved to :data:`ARTIFACTS` as
    ``failed-<name>.png`` and ``.txt``, with the app's status and the control rate;
    where they are (or why they could not be taken), in a line."""
    ARTIFACTS.mkdir(exist_ok=True)
    stem = ARTIFACTS / f"failed-{name}"
    try:
        web.page.screenshot(path=f"{stem}.png", timeout=1e3 * WAIT)
        text = web.page.inner_text("body", timeout=1e3 * WAIT)
    except Exception as error:  # the page may be what failed: say so, never mask the failure
        return f"no screenshot of the page: {type(error).__name__}: {error}"
    timing = web.control.timing()
    Path(f"{stem}.txt").write_text(
        f"{text}\n\n-- the control thread: {timing.achieved_rate:.0f} Hz achieved, "
        f"{timing.deadline_misses} deadline misses; its error: {web.control.error}\n")
    return f"the page: {stem}.png and .txt"


def still_failure(previous: np.ndarray, pixels: np.ndarray) -> str:
    """What changed between the last two screenshots of a canvas that did not hold still,
    both saved (with the changed pixels in white) to :data:`ARTIFACTS` to be looked at."""
    from PIL import Image

    changed = np.abs(pixels - previous).max(axis=2) > 24
    rows, cols = np.nonzero(changed)
    ARTIFACTS.mkdir(exist_ok=True)
    stamp = time.strftime("%H%M%S")
    for label, image in (("before", previous), ("after", pixels),
                         ("changed", np.repeat(255 * changed[..., None], 3, axis=2))):
        Image.fromarray(image.astype(np.uint8)).save(ARTIFACTS / f"unsteady-{stamp}-{label}.png")
    return (f"{100 * changed.mean():.2f} % of the pixels changed, within columns "
            f"{cols.min()}-{cols.max()} and rows {rows.min()}-{rows.max()} "
            f"({ARTIFACTS}/unsteady-{stamp}-*.png)")


def look_at_target(web, distance: float | None = None) -> None:
    """Camera in front of the target gizmo, from the front-right and above; by default
    2.5 gizmo sizes away (the gizmo then spans the same part of the view whatever its
    size)."""
    if distance is None:
        distance = 2.5 * web.ui.scene.target_gizmo.scale
    target = web.app.console.target.translation.copy()
    direction = np.array([0.55, -0.65, 0.45])
    set_camera(web.client, target + distance * direction / np.linalg.norm(direction), target)


def plan_drag(web, distance: float, steps: int, prefer_sign: float = 1.0, ee: int = 0):
    """Where to grab EE ``ee``'s target gizmo and how to move the mouse for ``distance`` m.

    Grabs a translation arrow near its tip (88 % of its length: past the rotation arcs at
    65 %), keeps the path on the free part of the canvas (not under the control panel, not
    over the constraints' own gizmos nor the other EEs') and prefers the arrow that looks
    longest on screen.
    """
    page, camera = web.page, web.client.camera
    box = scene_canvas(page)
    panel = page.get_by_role("tab", name="Teleop", exact=True).bounding_box()
    panel_left = panel["x"] - 40.0 if panel else box.x + 0.7 * box.width
    right = pin.Quaternion(*camera.wxyz).normalized().matrix()[:, 0]  # camera x, in the world
    avoid = []  # the constraints' own gizmos: circles on screen
    others = [markers["gizmo"] for markers in list(web.ui.constraint_markers.nodes.values())]
    others += [handle for k, handle in enumerate(web.ui.scene.target_gizmos) if k != ee]
    for handle in others:
        position, scale = np.asarray(handle.position), handle.scale
        centre, edge = project(camera, box, [position, position + scale * right])
        avoid.append((centre, 1.2 * np.linalg.norm(edge - centre) + 10.0))
    gizmo = web.ui.scene.target_gizmos[ee]
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
    target0, ee0 = app.console.target.translation.copy(), ee_position(app)
    with Sampler(app) as sampler:
        times = drag(web, plan)
        moved = wait_until(
            lambda: np.linalg.norm(app.console.target.translation - target0) > 0.5 * distance, WAIT,
            "the server-side target to follow the drag (did the mouse grab the gizmo?)")
        target1 = app.console.target.translation.copy()
        unit = (target1 - target0) / np.linalg.norm(target1 - target0)
        wait_until(lambda: np.linalg.norm(ee_position(app) - app.console.target.translation) < 1e-4,
                   WAIT, "the EE to reach the dragged target")
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
        settle_after_up=settled - times.up, moves_wall=times.moves, up_wall=times.up,
        max_sampled_error=float(np.nanmax([s.constraint_error for s in samples])))


def worst_of_trace(trace: dict[str, np.ndarray], since: float, result) -> str:
    """Where the largest constraint error of ``trace`` (:func:`trace_since` ``since``)
    lies in loop time against a drag's (``result``, :func:`measured_drag`) first mouse
    move and release, and the statuses sampled around it: what a failure says."""
    worst = int(np.argmax(trace["constraint_error"]))
    at = float(trace["t"][worst])

    def loop_time(wall: float) -> float:
        after = [s.t for s in result.samples if s.wall >= wall and np.isfinite(s.t)]
        return after[0] - since if after else math.nan

    near = sorted({s.status for s in result.samples if abs(s.t - at) <= 0.05})
    return (f"{trace['constraint_error'][worst]:.3g} m at {at - since:.3f} s (loop time since "
            f"{since:.3f} s; the drag's first move reached the loop by "
            f"{loop_time(result.moves_wall[0]):.3f} s, its release by "
            f"{loop_time(result.up_wall):.3f} s); EE error {trace['ee_error'][worst]:.3g} m, "
            f"constraint velocity {trace['constraint_velocity'][worst]:.3g} m/s; statuses "
            f"sampled within 50 ms: {near or 'none'}")


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
          f"{1.0 / control.app.robots.config.dt:.0f} Hz), {control.deadline_misses} deadline misses")


def wait_for(predicate, timeout: float):
    """``predicate()``'s first true value, polled every 10 ms; ``AssertionError`` after
    ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.01)
    raise AssertionError(f"timed out after {timeout:g} s")
