"""The SpaceMouse (docs/design.md section 19.4): its HID reports decoded, written here
byte by byte in the documented layouts, the deadband and speed curve against their
formula, and the source's samples."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from hypothesis import given, strategies as st

from teleop.inputs import CLUTCH, MODE
from teleop.inputs.spacemouse import DEVICES, ReportState, SpaceMouse, SpeedCurve

NAVIGATOR = next(m for m in DEVICES if m.name == "SpaceNavigator")  # split reports
COMPACT = next(m for m in DEVICES if m.product_id == 0xC635)  # split, vendor 0x256f
int16 = st.integers(-32768, 32767)


def device_axes(x: int, y: int, z: int, full_scale: float = 350.0) -> np.ndarray:
    """The device frame (x right, y up, z towards the operator) of raw counts x right, y
    towards the user, z down: (x, -z, y), each over the full scale, clipped."""
    return np.clip(np.array([x, -z, y]) / full_scale, -1.0, 1.0)


def test_split_reports_translation_rotation_and_buttons():
    state = ReportState(NAVIGATOR.full_scale)
    state.update(struct.pack("<B3h", 1, 175, -70, 350))  # right, towards the user, down
    assert state.translation == pytest.approx([0.5, -1.0, -0.2])
    assert state.rotation == pytest.approx([0.0, 0.0, 0.0])
    state.update(struct.pack("<B3h", 2, -35, 0, 70))
    assert state.rotation == pytest.approx([-0.1, -0.2, 0.0])
    assert state.translation == pytest.approx([0.5, -1.0, -0.2])  # kept from report 1
    state.update(bytes([3, 0b01, 0]))
    assert state.buttons == CLUTCH
    state.update(bytes([3, 0b10, 0]))
    assert state.buttons == MODE
    state.update(bytes([3, 0b11]))
    assert state.buttons == CLUTCH | MODE


def test_the_compact_sends_split_reports():
    """Its report log (7-byte reports 1 and 2, CloudCompare pull request 2339) as bytes."""
    state = ReportState(COMPACT.full_scale)
    state.update(bytes.fromhex("02 20 00 00 00 17 00"))
    state.update(bytes.fromhex("01 12 00 00 00 f8 00"))
    assert state.rotation == pytest.approx(device_axes(0x20, 0, 0x17))
    assert state.translation == pytest.approx(device_axes(0x12, 0, 0xF8))


def test_each_raw_direction_lands_on_the_device_axis_it_means():
    """A push right is +x, a lift of the cap (raw -z) +y, a pull towards the operator
    (raw +y) +z; a rotation turns like its axis (the frames are right-handed)."""
    state = ReportState()
    for raw, expected in (((350, 0, 0), [1, 0, 0]), ((0, 0, -350), [0, 1, 0]),
                          ((0, 350, 0), [0, 0, 1])):
        state.update(struct.pack("<B3h", 1, *raw))
        state.update(struct.pack("<B3h", 2, *raw))
        assert state.translation == pytest.approx(expected)
        assert state.rotation == pytest.approx(expected)


def test_the_combined_report_carries_all_six_axes():
    state = ReportState()
    state.update(struct.pack("<B6h", 1, 10, 20, 30, -40, -50, -60))
    assert state.translation == pytest.approx(device_axes(10, 20, 30))
    assert state.rotation == pytest.approx(device_axes(-40, -50, -60))
    state.update(struct.pack("<B6h", 1, 0, 0, 0, 0, 0, 0) + bytes(6))  # padded by a receiver
    assert not np.any(state.translation) and not np.any(state.rotation)


def test_a_pro_button_report_reads_its_first_two_bits():
    """The Pro family's report 3 has four bytes of buttons: Menu (bit 0) and Fit (bit 1)
    are the clutch and the mode; the others change nothing."""
    state = ReportState()
    state.update(struct.pack("<BI", 3, 0xFFFF_FFFC))
    assert state.buttons == 0
    state.update(struct.pack("<BI", 3, 0x0000_1003))
    assert state.buttons == CLUTCH | MODE


@pytest.mark.parametrize("report, message", [
    (struct.pack("<B2h", 1, 1, 2), "report 1 has 4 bytes, needs 6"),
    (struct.pack("<B2h", 2, 1, 2), "report 2 has 4 bytes, needs 6"),
    (bytes([7, 0, 0]), "report id 7"),
    (bytes([3]), "report 3 has 0 bytes"),
    (b"", "empty"),
])
def test_a_report_that_cannot_be_read_is_a_value_error_naming_it(report, message):
    with pytest.raises(ValueError, match=message):
        ReportState().update(report)


def test_a_full_scale_must_be_positive():
    with pytest.raises(ValueError, match="full_scale"):
        ReportState(0.0)


@given(counts=st.tuples(int16, int16, int16, int16, int16, int16))
def test_any_counts_decode_to_bounded_axes_and_a_bounded_twist(counts):
    state = ReportState()
    state.update(struct.pack("<B6h", 1, *counts))
    assert state.translation == pytest.approx(device_axes(*counts[:3]), abs=1e-15)
    assert state.rotation == pytest.approx(device_axes(*counts[3:]), abs=1e-15)
    curve = SpeedCurve()
    twist = curve.twist(state.translation, state.rotation)
    assert np.all(np.abs(twist[:3]) <= curve.max_linear)
    assert np.all(np.abs(twist[3:]) <= curve.max_angular)


@pytest.mark.parametrize("u", [-1.0, -0.55, -0.1000001, -0.1, 0.0, 0.0999999, 0.1, 0.1000001,
                               0.3, 0.75, 1.0])
def test_the_speed_curve_is_its_formula(u):
    curve = SpeedCurve(deadband=0.1, power=2.0)
    expected = 0.0 if abs(u) <= 0.1 else np.sign(u) * ((abs(u) - 0.1) / 0.9) ** 2
    assert curve.shaped(np.array([u]))[0] == pytest.approx(expected, abs=1e-15)


def test_a_bad_speed_curve_is_refused():
    with pytest.raises(ValueError, match="deadband"):
        SpeedCurve(deadband=1.0)


def test_the_source_offers_the_twist_each_report_asks_for():
    source = SpaceMouse(NAVIGATOR)
    curve = source.curve
    source.handle_report(struct.pack("<B3h", 1, 350, 0, 0), 1.0)  # a full push right
    sample = source.take()
    assert sample.kind == "twist" and sample.sequence == 1 and sample.arrival == 1.0
    assert sample.values == pytest.approx([curve.max_linear, 0, 0, 0, 0, 0])
    source.handle_report(struct.pack("<B3h", 2, 0, 0, -210), 2.0)  # twist the cap
    source.handle_report(bytes([3, 1]), 3.0)  # the left button: the clutch
    sample = source.take()
    yaw = -((0.6 - 0.1) / 0.9) ** 2 * curve.max_angular  # rz up = -(raw z)
    assert sample.values == pytest.approx([curve.max_linear, 0, 0, 0, -yaw, 0])
    assert sample.clutched and sample.sequence == 3
    assert source.counts["superseded"] == 1
    source.handle_report(bytes([9, 9]), 4.0)
    assert source.counts["malformed"] == 1 and source.take() is None


def test_open_without_a_device_is_one_line():
    with pytest.raises(ValueError) as raised:
        SpaceMouse.open()
    assert "SpaceMouse" in str(raised.value) and "\n" not in str(raised.value)


def test_a_combined_device_offers_its_clipped_twist_per_report():
    """A SpaceMouse Wireless's 13-byte reports; counts past the full scale are a full push."""
    source = SpaceMouse(next(m for m in DEVICES if m.product_id == 0xC62E))
    curve = source.curve
    source.handle_report(struct.pack("<B6h", 1, 700, 0, -32768, 0, 0, 0), 1.0)
    sample = source.take()
    assert sample.values == pytest.approx([curve.max_linear, curve.max_linear, 0, 0, 0, 0])
    source.handle_report(struct.pack("<B6h", 1, 0, 0, 0, 0, 35 + 175, 0), 2.0)
    source.handle_report(bytes([3, 2]), 3.0)  # the right button: the mode
    sample = source.take()
    tilt = ((0.6 - 0.1) / 0.9) ** 2 * curve.max_angular  # raw ry (towards the user) is +z
    assert sample.values == pytest.approx([0, 0, 0, 0, 0, tilt])
    assert sample.buttons == MODE and not sample.clutched and sample.sequence == 3


class RecordedDevice:
    """A HID device that plays recorded reports, then answers nothing (or fails): what
    easyhid's device gives the reading thread."""

    def __init__(self, reports: list[bytes], then_fail: bool) -> None:
        self.reports, self.then_fail, self.closed = list(reports), then_fail, False

    def read(self, size: int, timeout_ms: int) -> bytes:
        if self.reports:
            return self.reports.pop(0)
        if self.then_fail:
            raise OSError("read error: device disconnected")
        time.sleep(timeout_ms / 1e3)
        return b""

    def close(self) -> None:
        self.closed = True


@pytest.mark.parametrize("then_fail", [True, False])
def test_a_device_that_fails_or_falls_silent_while_deflected_stops_the_motion(then_fail):
    """Unplugged (a read error) or out of radio range (no report while the cap is pushed):
    the source offers a zero twist; the first also says so in its problem."""
    push = struct.pack("<B3h", 1, 350, 0, 0)
    source = SpaceMouse(NAVIGATOR, device=RecordedDevice([push], then_fail))
    started = time.monotonic()  # before the reading thread: its first report comes after
    source.start()
    try:
        while source.counts_now().get("accepted", 0) < 2:  # the push, then the stop
            assert time.monotonic() - started < 10.0, "the motion was not stopped"
            time.sleep(0.005)
        stopped = source.take()
        assert stopped.kind == "twist" and not any(stopped.values) and stopped.sequence == 2
        if then_fail:
            assert "stopped answering" in source.problem
        else:  # after the silence limit, not before
            assert time.monotonic() - started >= 0.2 and source.problem == ""
    finally:
        source.close()
    assert source._device.closed
