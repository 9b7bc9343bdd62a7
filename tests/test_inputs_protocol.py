"""The network master's protocol and receiver (docs/design.md section 19.2): commands
decode to what was encoded; malformed, hostile, stale, replayed and foreign datagrams are
dropped and counted, none applied."""

from __future__ import annotations

import hmac
import math
import socket
import struct
import time

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from teleop.inputs import (CLUTCH, DROP_REASONS, Feedback, FeedbackState, PacketError,
                           UdpMaster, decode_command, decode_feedback, encode_command,
                           encode_feedback)
from teleop.inputs.protocol import (COMMAND_FORMAT, COMMAND_SIZE, FEEDBACK_SIZE,
                                    MAX_DEVICE_POSITION, MAX_DEVICE_SPEED, TAG_SIZE, tag)

#: the key both sides hold in these tests
KEY = bytes(range(32))

finite = st.floats(-1.0, 1.0, allow_nan=False)


@given(position=st.tuples(finite, finite, finite),
       quaternion=st.tuples(finite, finite, finite, finite).filter(
           lambda q: 0.6 < math.sqrt(sum(v * v for v in q)) < 1.9),
       sequence=st.integers(0, 2**32 - 1), device_time=st.floats(0.0, 1e6),
       buttons=st.integers(0, 3))
def test_a_pose_command_decodes_to_what_was_sent(position, quaternion, sequence, device_time,
                                                 buttons):
    datagram = encode_command("pose", [*position, *quaternion], sequence, device_time, 1,
                              buttons, key=KEY)
    assert len(datagram) == COMMAND_SIZE == 108
    command = decode_command(datagram, ee=1, key=KEY)
    norm = math.sqrt(sum(v * v for v in quaternion))
    assert command.kind == "pose" and command.sequence == sequence
    assert command.buttons == buttons and command.device_time == device_time
    assert command.values[:3] == pytest.approx(position, abs=0.0)
    assert command.values[3:] == pytest.approx([v / norm for v in quaternion], rel=1e-12)


@given(twist=st.tuples(*[st.floats(-3.0, 3.0)] * 6))
def test_a_twist_command_decodes_to_what_was_sent(twist):
    command = decode_command(encode_command("twist", twist, 7, 1.5, key=KEY), ee=0, key=KEY)
    assert command.kind == "twist" and command.values == (*twist, 0.0)


@given(wrench=st.tuples(*[st.floats(-10.0, 10.0)] * 6), sequence=st.integers(0, 2**32 - 1),
       state=st.sampled_from(list(FeedbackState)), measured=st.booleans())
def test_a_feedback_decodes_to_what_was_sent(wrench, sequence, state, measured):
    sent = Feedback(state, 0, sequence, sequence // 2, 3.25, wrench, 4e-4, measured,
                    launch=sequence * 7919)
    datagram = encode_feedback(sent, KEY)
    assert len(datagram) == FEEDBACK_SIZE == 104
    assert decode_feedback(datagram, KEY) == sent
    with pytest.raises(PacketError, match="tag"):
        decode_feedback(datagram, bytes(32))  # a forged feedback: never rendered


def _valid(sequence: int = 1, device_time: float = 0.0) -> list:
    """The fields of a valid pose command (a hello: launch 0), to spoil one by one."""
    return [b"CJMI", 3, 1, 0, 0, sequence, device_time, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1,
            0]


def tagged(body: bytes) -> bytes:
    return body + tag(KEY, body)


def encode_v2(rng: np.random.Generator) -> bytes:
    """A version-2 command (100 bytes, no launch), tagged with the right key."""
    body = struct.pack("<4sBBBBId7dQ", b"CJMI", 2, 1, 0, 0, int(rng.integers(1, 1000)), 0.0,
                       0, 0, 0, 1, 0, 0, 0, 1)
    return body + tag(KEY, body)


def hostile_datagrams(rng: np.random.Generator, count: int) -> list[tuple[bytes, str]]:
    """``count`` datagrams, each spoilt one way, with the reason it must be dropped for."""
    spoilers = []
    valid = tagged(COMMAND_FORMAT.pack(*_valid()))

    def field(index: int, value) -> bytes:
        fields = _valid()
        fields[index] = value
        return tagged(COMMAND_FORMAT.pack(*fields))

    spoilers.append(lambda: (valid[:rng.integers(0, COMMAND_SIZE)], "malformed"))  # truncated
    spoilers.append(lambda: (valid + bytes(rng.integers(1, 1500)), "malformed"))  # too long
    spoilers.append(lambda: (rng.bytes(COMMAND_SIZE), "malformed"))  # noise, bad magic
    spoilers.append(lambda: (field(1, int(rng.choice([0, 1, 2, 4, 255]))), "version"))
    spoilers.append(lambda: (struct.pack("<4sBBBBId7d", b"CJMI", 1, 1, 0, 0, 1, 0.0, 0, 0, 0,
                                         1, 0, 0, 0), "version"))  # a version-1 master
    spoilers.append(lambda: (encode_v2(rng), "version"))  # a version-2 master, well tagged
    spoilers.append(lambda: (field(15, int(rng.integers(1, 2**63))), "other_launch"))
    spoilers.append(lambda: (COMMAND_FORMAT.pack(*_valid()) + rng.bytes(TAG_SIZE),
                             "unauthenticated"))  # a forged tag
    spoilers.append(lambda: (COMMAND_FORMAT.pack(*_valid()) + tag(bytes(32), COMMAND_FORMAT.pack(
        *_valid())), "unauthenticated"))  # another key's
    spoilers.append(lambda: (field(2, int(rng.choice([0, 3, 200]))), "malformed"))  # kind
    spoilers.append(lambda: (field(4, int(rng.integers(4, 256))), "malformed"))  # buttons
    spoilers.append(lambda: (field(3, int(rng.integers(1, 256))), "wrong_ee"))
    spoilers.append(lambda: (field(int(rng.integers(6, 14)),
                                   float(rng.choice([np.nan, np.inf, -np.inf]))), "not_finite"))
    spoilers.append(lambda: (field(int(rng.integers(7, 10)),
                                   float(rng.choice([-1, 1]) * rng.uniform(1.01, 1e300)
                                         * MAX_DEVICE_POSITION)), "out_of_range"))
    spoilers.append(lambda: (field(10, 0.0), "out_of_range"))  # a zero quaternion
    spoilers.append(lambda: (field(10, 1e10), "out_of_range"))  # a huge one
    twist = [b"CJMI", 3, 2, 0, 0, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1, 0]

    def fast_twist() -> tuple[bytes, str]:
        fields = list(twist)
        fields[int(rng.integers(7, 13))] = 1.01 * MAX_DEVICE_SPEED[1]
        return tagged(COMMAND_FORMAT.pack(*fields)), "out_of_range"
    spoilers.append(fast_twist)
    return [spoilers[int(rng.integers(len(spoilers)))]() for _ in range(count)]


def test_ten_thousand_hostile_datagrams_are_dropped_and_counted():
    """10,000 hostile datagrams over a real socket, between valid commands: no crash,
    none offered to the control tick, each counted under the reason written here."""
    rng = np.random.default_rng(24)
    datagrams = hostile_datagrams(rng, 10_000)
    expected = {reason: sum(1 for _, r in datagrams if r == reason) for reason in DROP_REASONS}
    master = UdpMaster(port=0, key=KEY)
    master.start()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        first = encode_command("pose", [0, 0, 0, 1, 0, 0, 0], 1, time.perf_counter(), key=KEY,
                               launch=master.launch)
        sender.sendto(first, ("127.0.0.1", master.port))
        _wait_for(lambda: master.counts["accepted"] == 1)
        assert master.take().sequence == 1
        for index, (datagram, _) in enumerate(datagrams):
            sender.sendto(datagram, ("127.0.0.1", master.port))
            if index % 200 == 0:  # let the receiver keep up: a full socket buffer drops
                _wait_for(lambda: master.counts["received"] >= index + 2)
        _wait_for(lambda: master.counts["received"] == 10_001)
        assert master.take() is None  # none of them was offered
        assert master.counts["accepted"] == 1
        assert {reason: master.counts[reason] for reason in DROP_REASONS} == \
            {reason: expected[reason] for reason in DROP_REASONS}
        assert master.dropped() == 10_000
        # still alive: a valid command after all that is taken
        sender.sendto(encode_command("pose", [0, 0, 0, 1, 0, 0, 0], 2, time.perf_counter(),
                                     key=KEY, launch=master.launch), ("127.0.0.1", master.port))
        _wait_for(lambda: master.counts["accepted"] == 2)
        assert master.take().sequence == 2
    finally:
        sender.close()
        master.close()


def _wait_for(condition, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.001)


def test_replayed_reordered_stale_and_foreign_commands_are_dropped_and_counted():
    """Driven through :meth:`UdpMaster.handle` with chosen arrival times (no socket
    timing): the sequence, the transit and the sender decide."""
    master = UdpMaster(port=0, max_age=0.1, key=KEY)
    try:
        here, there = ("127.0.0.1", 5000), ("127.0.0.1", 5001)
        pose = [0, 0, 0, 1, 0, 0, 0]

        def send(sequence, device_time, arrival, sender=here, buttons=0, stream=1):
            master.handle(encode_command("pose", pose, sequence, device_time, 0, buttons,
                                         key=KEY, stream=stream, launch=master.launch),
                          sender, arrival)

        send(10, 0.000, 50.001)  # transit 50.001: the clock offset
        send(11, 0.001, 50.002)
        send(11, 0.001, 50.003)  # replayed
        send(9, 0.002, 50.004)  # reordered
        send(14, 0.004, 50.005)  # 12 and 13 lost
        send(15, 0.005, 50.2)  # 0.194 s in transit beyond the offset: stale
        send(16, 0.006, 50.007, sender=there)  # foreign while the master is live
        send(17, 0.007, 50.0075, buttons=CLUTCH)  # faster than ever: a new offset
        counts = master.counts
        # lost: 12 and 13, and the master's 16 (15 arrived, stale; the 16 that came was
        # another sender's)
        assert (counts["received"], counts["accepted"], counts["out_of_order"], counts["lost"],
                counts["stale"], counts["foreign"], counts["superseded"]) == (8, 4, 2, 3, 1, 1, 3)
        sample = master.take()
        assert sample.sequence == 17 and sample.clutched and sample.arrival == 50.0075
        master.release()  # the watchdog: the master stays bound
        send(1, 900.0, 60.0, sender=there)  # its stream from elsewhere: foreign
        send(12, 0.01, 60.01)  # its own, replayed: out of order
        assert master.take() is None and master.master == here
        assert (counts["foreign"], counts["out_of_order"]) == (2, 3)
        send(900, 10.0, 60.02)  # it resumes (a silence's gap is not lost)
        assert master.take().sequence == 900 and counts["lost"] == 3
        master.release()
        send(1, 900.0, 61.0, sender=there, stream=2)  # a restarted master (holds the key)
        assert master.take().sequence == 1 and master.master == there
        send(901, 10.1, 61.01)  # the old one while the new is live: foreign
        master.release()
        send(902, 10.2, 61.2)  # the stream it left, replayed after a silence
        assert master.take() is None and (counts["foreign"], counts["replayed"]) == (3, 1)
        assert master.master == there and counts["accepted"] == 6
    finally:
        master.close()


def test_a_port_in_use_is_a_value_error_naming_it():
    taken = UdpMaster(port=0)
    try:
        with pytest.raises(ValueError, match=f"udp 127.0.0.1:{taken.port}"):
            UdpMaster(port=taken.port)
    finally:
        taken.close()


@settings(max_examples=300)
@given(datagram=st.binary(max_size=200))
def test_any_bytes_decode_or_raise_a_packet_error(datagram):
    try:
        command = decode_command(datagram, ee=0, key=KEY)
    except PacketError as error:
        assert error.reason in DROP_REASONS
    else:
        assert all(math.isfinite(v) for v in command.values)


def test_the_command_layout_is_the_documented_one():
    """The byte offsets docs/inputs.md gives, read back with plain struct calls."""
    datagram = encode_command("pose", [1, 2, 3, 1, 0, 0, 0], 0x01020304, 2.5, 1, CLUTCH,
                              key=KEY, stream=0x0102030405060708, launch=0x1112131415161718)
    assert datagram[:4] == b"CJMI" and datagram[4:8] == bytes([3, 1, 1, 1])
    assert struct.unpack_from("<I", datagram, 8) == (0x01020304,)
    assert struct.unpack_from("<d", datagram, 12) == (2.5,)
    assert struct.unpack_from("<7d", datagram, 20) == (1, 2, 3, 1, 0, 0, 0)
    assert struct.unpack_from("<Q", datagram, 76) == (0x0102030405060708,)
    assert struct.unpack_from("<Q", datagram, 84) == (0x1112131415161718,)
    assert datagram[92:] == hmac.digest(KEY, datagram[:92], "sha256")[:16]
    feedback = encode_feedback(Feedback(FeedbackState.HELD, 1, 5, 4, 2.5, (0.0,) * 6, 0.0,
                                        launch=0x2122232425262728), KEY)
    assert feedback[4] == 3 and struct.unpack_from("<Q", feedback, 80) == (0x2122232425262728,)
    assert feedback[88:] == hmac.digest(KEY, feedback[:88], "sha256")[:16]
