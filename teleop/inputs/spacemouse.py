"""A 3Dconnexion SpaceMouse: rate control from its HID reports (docs/design.md section
19.4).

**Reports.** Every model sends three input reports, an id byte then the payload:

* report 1, the *split* layout (SpaceNavigator, SpaceExplorer, SpaceMouse Pro, the
  SpaceMouse Compact, ...): the translation x, y, z, three int16 little-endian (7 bytes);
  report 2 then carries the rotation rx, ry, rz the same way;
* report 1, the *combined* layout (the SpaceMouse Wireless, Pro Wireless, Enterprise):
  all six, translation then rotation (13 bytes), and no report 2;
* report 3, the buttons: a bitfield after the id, bit 0 the clutch (held), bit 1 the
  mode. Those are the left and right buttons of the two-button models (SpaceNavigator,
  Compact, Wireless), buttons 1 and 2 of the SpaceExplorer and SpacePilot, Menu and Fit
  of the Pro family (SpacePilot Pro, SpaceMouse Pro, Pro Wireless, Enterprise); the
  SpaceMouse USB has none.

The layout is read from the length of each report 1, not from the model: the Compact,
of vendor 0x256f like the combined models, sends split reports (7 bytes, ids 1 and 2).
hidapi returns a report at its own length (hidraw, macOS) or padded to the device's
longest input report (Windows), so a split device's report 1 never reaches 13 bytes. A
report 1 or 2 shorter than its payload, a report 3 without its bitfield, or another id, is refused
(``ValueError`` naming it).

**Axes.** The device reports x to the right, y towards the user and z down (pushing the
cap is +z), and its rotations right-handed about those axes (the HID usage tables'
convention; the frame is right-handed). The device frame of :mod:`teleop.inputs.mapping`
is x right, y up, z towards the operator, so ``u_device = A u_raw`` with

    A = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]

(up is -z_raw, towards the operator is +y_raw). ``A`` is a proper rotation (a quarter
turn about x, det A = 1), so the same ``A`` turns the rotation axes: a rotation vector
keeps its right-hand rule.

**Speed curve.** Each axis's counts over its model's full scale, ``u`` clipped to
[-1, 1]; a deadband ``d`` and a curve of power ``p``:

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
#: the payload bytes of three axes (int16 each)
AXES_BYTES = 6
#: the bytes read per report (the longest payload and its id, with room for padding)
READ_SIZE = 64
#: the reading thread's wait for a report before it checks whether to stop (ms)
READ_TIMEOUT_MS = 50
#: a deflected cap reports continuously; silent this long while deflected (s), the link
#: is taken as lost and the motion stopped (a wireless receiver out of range)
SILENT_DEFLECTED = 0.2


@dataclass(frozen=True)
class DeviceModel:
    """A SpaceMouse model: its USB ids and its axes' full scale."""

    name: str
    vendor_id: int
    product_id: int
    full_scale: float = 350.0  # counts of a full push


#: the known models; the layout each sends is in the comment (the decoding reads it from
#: the report's length)
DEVICES = (
    DeviceModel("SpaceNavigator", 0x046D, 0xC626),  # split
    DeviceModel("SpaceNavigator for Notebooks", 0x046D, 0xC628),  # split
    DeviceModel("SpaceExplorer", 0x046D, 0xC627),  # split
    DeviceModel("SpacePilot", 0x046D, 0xC625),  # split
    DeviceModel("SpacePilot Pro", 0x046D, 0xC629),  # split
    DeviceModel("SpaceMouse Pro", 0x046D, 0xC62B),  # split
    DeviceModel("SpaceMouse Compact", 0x256F, 0xC635),  # split
    DeviceModel("SpaceMouse USB", 0x256F, 0xC641),  # split, no buttons
    DeviceModel("SpaceMouse Wireless", 0x256F, 0xC62E),  # combined
    DeviceModel("SpaceMouse Wireless (receiver)", 0x256F, 0xC62F),  # combined
    DeviceModel("SpaceMouse Wireless", 0x256F, 0xC63A),  # combined, a newer one
    DeviceModel("SpaceMouse Pro Wireless", 0x256F, 0xC631),  # combined
    DeviceModel("SpaceMouse Pro Wireless (receiver)", 0x256F, 0xC632),  # combined
    DeviceModel("SpaceMouse Pro Wireless (Bluetooth)", 0x256F, 0xC638),  # combined
    DeviceModel("SpaceMouse Enterprise", 0x256F, 0xC633),  # combined
    DeviceModel("3Dconnexion Universal Receiver", 0x256F, 0xC652),  # combined
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
    sends the translation and the rotation apart, so each keeps the other's last)."""

    def __init__(self, full_scale: float = 350.0) -> None:
        if not full_scale > 0.0:
            raise ValueError(f"a SpaceMouse's full_scale must be positive, not {full_scale}")
        self.full_scale = full_scale
        self.translation = np.zeros(3)  # normalised, device frame
        self.rotation = np.zeros(3)
        self.buttons = 0  # CLUTCH | MODE

    def update(self, report: bytes) -> None:
        """Read one report (its id first): report 1 of at least 12 payload bytes is the
        combined layout, of 6 to 11 the split one's translation. ``ValueError`` for a
        report too short or of an unknown id."""
        if not report:
            raise ValueError("an empty SpaceMouse report")
        report_id, payload = report[0], bytes(report[1:])
        needed = {TRANSLATION: AXES_BYTES, ROTATION: AXES_BYTES, BUTTONS: 1}
        if report_id not in needed:
            raise ValueError(f"SpaceMouse report id {report_id} is none of "
                             f"{sorted(needed)} (translation, rotation, buttons)")
        if len(payload) < needed[report_id]:
            raise ValueError(f"SpaceMouse report {report_id} has {len(payload)} bytes, "
                             f"needs {needed[report_id]}")
        if report_id == TRANSLATION:
            self.translation = decode_axes(payload[:AXES_BYTES], self.full_scale)
            if len(payload) >= 2 * AXES_BYTES:
                self.rotation = decode_axes(payload[AXES_BYTES:2 * AXES_BYTES],
                                            self.full_scale)
        elif report_id == ROTATION:
            self.rotation = decode_axes(payload[:AXES_BYTES], self.full_scale)
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
        self.state = ReportState(model.full_scale)
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
        self.count("received")
        try:
            self.state.update(report)
        except ValueError:
            self.count("malformed")
            return
        self._sequence += 1
        twist = self.curve.twist(self.state.translation, self.state.rotation)
        self.offer(InputSample("twist", tuple(float(v) for v in twist), self.state.buttons,
                               self._sequence, arrival))

    def _read(self) -> None:
        last_report = time.perf_counter()
        while not self._stop.is_set():
            try:
                report = self._device.read(READ_SIZE, READ_TIMEOUT_MS)
            except Exception as error:  # unplugged: stop the motion and say so
                self.problem = f"the {self.model.name} stopped answering ({error})"
                self.stop_motion(time.perf_counter())
                return
            now = time.perf_counter()
            if report:
                last_report = now
                self.handle_report(bytes(report), now)
            elif now - last_report > SILENT_DEFLECTED and self._moving():
                self.stop_motion(now)  # a deflected cap reports without pause: link lost

    def _moving(self) -> bool:
        return bool(np.any(self.curve.twist(self.state.translation, self.state.rotation)))

    def stop_motion(self, arrival: float) -> None:
        """Offer a zero twist (the device stopped answering, or went silent while its
        cap was deflected); the state rests until the next report."""
        self.state.translation, self.state.rotation = np.zeros(3), np.zeros(3)
        self._sequence += 1
        self.offer(InputSample("twist", (0.0,) * 6, 0, self._sequence, arrival))
