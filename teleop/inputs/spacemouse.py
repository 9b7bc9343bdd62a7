"""A 3Dconnexion SpaceMouse: rate control from its HID reports (docs/design.md section
19.4).

**Reports.** Two layouts, by product (:data:`DEVICES`):

* *split* (SpaceNavigator, SpaceExplorer, SpaceMouse Pro, ... of vendor 0x046d): report 1
  is the translation x, y, z and report 2 the rotation rx, ry, rz, each three int16
  little-endian after the report id (7 bytes);
* *combined* (the SpaceMouse Wireless, Compact, Pro Wireless, Enterprise of vendor
  0x256f): report 1 carries all six, translation then rotation (13 bytes);

and report 3, the buttons: a bitfield after the id, bit 0 the left button (the clutch,
held), bit 1 the right button (the mode). A report may be longer than its payload (a
receiver pads to its size); one shorter, or of another id, is refused (``ValueError``).

**Axes.** The device reports x to the right, y towards the user and z down (pushing the
cap is +z), rotations about those axes. The device frame of :mod:`teleop.inputs.mapping`
is x right, y up, z towards the operator, so ``u_device = A u_raw`` with

    A = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]     (a rotation: det A = 1)

for both the translation and the rotation axes.

**Speed curve.** Each axis's counts over its full scale, ``u`` clipped to [-1, 1]; a
deadband ``d`` and a curve of power ``p``:

    u' = sign(u) ((|u| - d) / (1 - d))^p    if |u| > d,    else 0

then ``v = v_max u'`` (m/s) for the translation, ``w = w_max u'`` (rad/s) for the
rotation: a light touch moves finely, a full push at the page's EE speed caps.
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import dataclass

import numpy as np

from .protocol import CLUTCH, MODE
from .source import InputSample, InputSource

#: the device's raw axes (x right, y towards the user, z down) in the device frame of
#: :mod:`teleop.inputs.mapping` (x right, y up, z towards the operator)
RAW_TO_DEVICE = np.array([[1.0, 0.0, 0.0],
                          [0.0, 0.0, -1.0],
                          [0.0, 1.0, 0.0]])
TRANSLATION, ROTATION, BUTTONS = 1, 2, 3  # report ids
#: the bytes read per report (the longest payload and its id, with room for padding)
READ_SIZE = 64
#: the reading thread's wait for a report before it checks whether to stop (ms)
READ_TIMEOUT_MS = 50


@dataclass(frozen=True)
class DeviceModel:
    """A SpaceMouse model: its USB ids, its report layout and its axes' full scale."""

    name: str
    vendor_id: int
    product_id: int
    combined: bool  # translation and rotation in one report 1
    full_scale: float = 350.0  # counts of a full push


DEVICES = (
    DeviceModel("SpaceNavigator", 0x046D, 0xC626, False),
    DeviceModel("SpaceNavigator for Notebooks", 0x046D, 0xC628, False),
    DeviceModel("SpaceExplorer", 0x046D, 0xC627, False),
    DeviceModel("SpacePilot", 0x046D, 0xC625, False),
    DeviceModel("SpacePilot Pro", 0x046D, 0xC629, False),
    DeviceModel("SpaceMouse Pro", 0x046D, 0xC62B, False),
    DeviceModel("SpaceMouse Wireless", 0x256F, 0xC62E, True),
    DeviceModel("SpaceMouse Wireless (receiver)", 0x256F, 0xC62F, True),
    DeviceModel("SpaceMouse Pro Wireless", 0x256F, 0xC631, True),
    DeviceModel("SpaceMouse Pro Wireless (receiver)", 0x256F, 0xC632, True),
    DeviceModel("SpaceMouse Enterprise", 0x256F, 0xC633, True),
    DeviceModel("SpaceMouse Compact", 0x256F, 0xC635, True),
)


@dataclass(frozen=True)
class SpeedCurve:
    """The deadband, the curve's power and the speeds of a full push."""

    deadband: float = 0.1
    power: float = 2.0
    max_linear: float = 0.05  # m/s
    max_angular: float = 0.5  # rad/s

    def __post_init__(self) -> None:
        if not (0.0 <= self.deadband < 1.0 and self.power >= 1.0
                and self.max_linear > 0.0 and self.max_angular > 0.0):
            raise ValueError("a speed curve needs a deadband in [0, 1), a power >= 1 and "
                             "positive speeds")

    def shaped(self, axes: np.ndarray) -> np.ndarray:
        """``u'`` of each normalised axis ``u``."""
        magnitude = (np.abs(axes) - self.deadband) / (1.0 - self.deadband)
        return np.where(np.abs(axes) > self.deadband,
                        np.sign(axes) * np.clip(magnitude, 0.0, 1.0) ** self.power, 0.0)

    def twist(self, translation: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """The rate command (v; w) of the normalised axes (device frame)."""
        return np.concatenate([self.max_linear * self.shaped(translation),
                               self.max_angular * self.shaped(rotation)])


def decode_axes(payload: bytes, full_scale: float) -> np.ndarray:
    """Three int16 little-endian counts, normalised by ``full_scale`` and clipped to
    [-1, 1], turned into the device frame (:data:`RAW_TO_DEVICE`)."""
    counts = np.array(struct.unpack("<3h", payload), dtype=float)
    return RAW_TO_DEVICE @ np.clip(counts / full_scale, -1.0, 1.0)


class ReportState:
    """The axes and buttons a SpaceMouse's reports have set so far (the split layout
    sends translation and rotation apart)."""

    def __init__(self, model: DeviceModel) -> None:
        self.model = model
        self.translation = np.zeros(3)  # normalised, device frame
        self.rotation = np.zeros(3)
        self.buttons = 0  # CLUTCH | MODE

    def update(self, report: bytes) -> None:
        """Read one report (its id first); ``ValueError`` for one too short or of an
        unknown id."""
        if not report:
            raise ValueError("an empty SpaceMouse report")
        report_id, payload = report[0], bytes(report[1:])
        needed = {TRANSLATION: 12 if self.model.combined else 6, ROTATION: 6, BUTTONS: 1}
        if report_id not in needed or (report_id == ROTATION and self.model.combined):
            raise ValueError(f"SpaceMouse report id {report_id} is not one of the "
                             f"{self.model.name}'s")
        if len(payload) < needed[report_id]:
            raise ValueError(f"SpaceMouse report {report_id} has {len(payload)} bytes, "
                             f"needs {needed[report_id]}")
        scale = self.model.full_scale
        if report_id == TRANSLATION:
            self.translation = decode_axes(payload[:6], scale)
            if self.model.combined:
                self.rotation = decode_axes(payload[6:12], scale)
        elif report_id == ROTATION:
            self.rotation = decode_axes(payload[:6], scale)
        else:
            self.buttons = (CLUTCH if payload[0] & 1 else 0) | (MODE if payload[0] & 2 else 0)


def first_line(error: Exception) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else "no message"


class SpaceMouse(InputSource):
    """A SpaceMouse as a rate-control source (:meth:`open` finds one). Silent at rest,
    so no watchdog; a read error (unplugged) offers a zero twist and stops, saying so in
    :attr:`problem`."""

    watchdog = False

    def __init__(self, model: DeviceModel, ee: int = 0, device=None,
                 curve: SpeedCurve = SpeedCurve()) -> None:
        super().__init__("spacemouse", ee)
        self.model = model
        self.curve = curve
        self.state = ReportState(model)
        self._device = device
        self._sequence = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="input spacemouse",
                                        daemon=True)

    @classmethod
    def open(cls, ee: int = 0, curve: SpeedCurve = SpeedCurve()) -> "SpaceMouse":
        """The first known SpaceMouse among the USB HID devices, opened; ``ValueError``
        in one line when hidapi or the device is missing."""
        try:
            from easyhid import Enumeration
            devices = Enumeration().find()
        except (ImportError, OSError, AttributeError) as error:
            raise ValueError("no SpaceMouse: the hidapi library is not available "
                             f"({type(error).__name__}: {first_line(error)}); "
                             "pip install -e '.[spacemouse]' and the system's libhidapi "
                             "(Debian: libhidapi-hidraw0)") from None
        models = {(m.vendor_id, m.product_id): m for m in DEVICES}
        for device in devices:
            model = models.get((device.vendor_id, device.product_id))
            if model is not None:
                try:
                    device.open()
                except Exception as error:  # permissions: a udev rule is missing
                    raise ValueError(f"the {model.name} cannot be opened ({error}): give "
                                     "this user access to its hidraw device") from None
                return cls(model, ee, device, curve)
        raise ValueError(f"no SpaceMouse among the {len(devices)} HID devices (known: "
                         f"{', '.join(sorted({m.name for m in DEVICES}))})")

    def start(self) -> None:
        if self._device is not None:
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(1.0)
        if self._device is not None:
            self._device.close()

    def handle_report(self, report: bytes, arrival: float) -> None:
        """One report: the state updated and the twist it now asks for offered (a
        report that cannot be read is counted ``malformed``)."""
        self.counts["received"] += 1
        try:
            self.state.update(report)
        except ValueError:
            self.counts["malformed"] += 1
            return
        self._sequence += 1
        twist = self.curve.twist(self.state.translation, self.state.rotation)
        self.offer(InputSample("twist", tuple(float(v) for v in twist), self.state.buttons,
                               self._sequence, arrival))

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                report = self._device.read(READ_SIZE, READ_TIMEOUT_MS)
            except Exception as error:  # unplugged: stop the motion and say so
                self.problem = f"the {self.model.name} stopped answering ({error})"
                self._sequence += 1
                self.offer(InputSample("twist", (0.0,) * 6, 0, self._sequence,
                                       time.perf_counter()))
                return
            if report:
                self.handle_report(bytes(report), time.perf_counter())

