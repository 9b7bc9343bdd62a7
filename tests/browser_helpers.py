"""Helpers for the end-to-end browser tests (tests/test_browser.py).

Everything here is bounded in time: a wait that does not come true raises
``AssertionError`` with what it was waiting for, it never hangs.

Projection: viser reports each client's camera in the OpenCV convention
(``P_world = R p_camera + t``, the camera looks along +z, image y points down, ``fov``
vertical). A world point therefore lands on the canvas at
``cx + f x / z, cy + f y / z`` with ``f = (h / 2) / tan(fov / 2)`` (CSS pixels).
"""

from __future__ import annotations

import io
import math
import os
import shutil
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

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


_ECHOES: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}


def _camera_echoes(client) -> list[tuple[np.ndarray, np.ndarray]]:
    """Camera poses (position, look at) the browser of ``client`` reported, in order."""
    if client.client_id not in _ECHOES:
        echoes = _ECHOES[client.client_id] = []
        client.camera.on_update(
            lambda camera: echoes.append((camera.position.copy(), camera.look_at.copy())))
    return _ECHOES[client.client_id]


def set_camera(client, position, look_at, timeout: float = 20.0) -> None:
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
        q = app.loops["main"].q.copy()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(robot.ee_frame)].translation.copy()


def trace_since(app, t0: float) -> dict[str, np.ndarray]:
    """The main robot's plotted history (50 samples/s) from loop time ``t0`` on."""
    trace = app.snapshot()["robots"]["main"]["trace"]
    keep = trace["t"] >= t0
    return {key: value[keep] for key, value in trace.items()}


@dataclass
class Sample:
    wall: float  # time.perf_counter()
    target: np.ndarray
    ee: np.ndarray
    constraint_error: float


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
            record = app.last_records.get("main")
            error = math.nan if record is None else max(record.constraint_error,
                                                        record.barrier_penetration)
            self.samples.append(Sample(time.perf_counter(), app.target.translation.copy(),
                                       ee_position(app), error))
            time.sleep(self.period)

    def __enter__(self) -> "Sampler":
        self._thread.start()
        wait_until(lambda: self.samples, 5.0, "the first sample")
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def first(self, predicate: Callable[[Sample], bool]) -> Sample | None:
        return next((s for s in list(self.samples) if predicate(s)), None)
