"""The network master is paired and authenticated (protocol version 3): datagrams from
anyone else - unauthenticated, forged, replayed, recorded at an earlier launch, an
old-protocol master, a flood - while the real master streams, or while it pauses, move the
EE 0 mm, never release or replace the master, and are counted; counters stay bounded
against forged numbers."""

from __future__ import annotations

import hmac
import socket
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from teleop import load_robot
from teleop.inputs import (Feedback, FeedbackState, MasterClient, PacketError, UdpMaster,
                           decode_command, decode_feedback, encode_command, encode_feedback,
                           read_key_file)
from teleop.inputs.protocol import COMMAND_FORMAT, TAG_SIZE
from web.app import ControlThread, TeleopApp
from web.ui.device_view import device_words

KEY = bytes(range(32))
HOME = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)

#: the attacker, another process: ``count`` datagrams as fast as it can, from two sockets
#: of its own: poses 5 cm away with a random tag, a forged sequence 2^32-1 and device time,
#: the master's own stream replayed (as recorded: the right tag), version-1 commands
ATTACKER = """
import os, socket, struct, sys
from teleop.inputs.protocol import COMMAND_FORMAT, TAG_SIZE, VERSION, encode_command
port, count, stream, key = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), bytes.fromhex(sys.argv[4])
launch = int(sys.argv[5])
def forged(sequence, device_time, stream):
    return COMMAND_FORMAT.pack(b"CJMI", VERSION, 1, 0, 0, sequence, device_time,
                               0.05, 0.05, 0.05, 1, 0, 0, 0, stream, launch) + os.urandom(TAG_SIZE)
recorded = [encode_command("pose", (0.05, 0, 0, 1, 0, 0, 0), s, 0.0, key=key, stream=stream,
                           launch=launch) for s in range(1, 101)]
kinds = [lambda k: forged(k, 0.0, 7), lambda k: forged(2**32 - 1, 1e300, stream),
         lambda k: recorded[k % 100],
         lambda k: struct.pack("<4sBBBBId7d", b"CJMI", 1, 1, 0, 0, k, 0.0, 0.05, 0, 0, 1, 0, 0, 0)]
sockets = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
for k in range(count):
    sockets[k % 2].sendto(kinds[k % 4](k), ("127.0.0.1", port))
print("sent", count, flush=True)
"""


class Streamer:
    """The real master: holds its device still, streaming at 200 Hz from a thread."""

    def __init__(self, port: int) -> None:
        self.client = MasterClient(port, key=KEY)
        self.running = threading.Event()
        self.running.set()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            if self.running.is_set():
                self.client.send_pose((0.0, 0.0, 0.0))
                self.client.feedback()
            time.sleep(0.005)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self.client.close()


def wait_for(condition, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


def ee_position(app) -> np.ndarray:
    return app.robots.loops["main"].ee_placements()[0].translation.copy()


def attack(master: UdpMaster, stream: int, count: int) -> None:
    """Run the attacker process to its end, and until the master has read everything."""
    before = master.counts_now().get("received", 0)
    done = subprocess.run([sys.executable, "-c", ATTACKER, str(master.port), str(count),
                           str(stream), KEY.hex(), str(master.launch)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0 and f"sent {count}" in done.stdout, done.stderr
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        # a probe datagram behind the flood, sent again until the queue has room for it:
        # read, it brings the socket's count of the datagrams the system dropped
        deadline = time.monotonic() + 60.0
        while (master.intruder or (None, None))[1] != probe.getsockname()[1]:
            assert time.monotonic() < deadline, "the queue never drained"
            probe.sendto(encode_command("pose", HOME, 1, 0.0, key=bytes(32)),  # another key:
                         ("127.0.0.1", master.port))  # an intrusion, live or released
            time.sleep(0.2)
    counts = master.counts_now()
    print(f"\n[attack] {count} datagrams sent, {counts['received'] - before} read by the "
          f"receiver (with the master's own), {counts.get('overflow', 0)} dropped by the "
          "system from the full queue")


@pytest.fixture
def console():
    app = TeleopApp(load_robot("sda10f"), controller="cjm", rate=500.0)
    app.constraints.add("hole", distance=0.08)
    master = UdpMaster(port=0, key=KEY)
    app.devices.attach(master)
    app.devices.set_input_timeout(0.5)  # a stall of the shared machine is not what is tested here
    control = ControlThread(app)
    control.start()
    streamer = Streamer(master.port)
    try:
        wait_for(lambda: app.devices[0].state == FeedbackState.FOLLOWING, "the master")
        yield app, master, streamer
    finally:
        streamer.close()
        control.stop()
        app.devices.close()


def test_a_flood_while_the_master_streams_moves_nothing_and_releases_nothing(console):
    app, master, streamer = console
    bound, target = master.master, app.console.targets[0].translation.copy()
    ee_start = ee_position(app)
    moved = []
    sampling = threading.Event()

    def sample() -> None:
        while not sampling.is_set():
            moved.append(float(np.linalg.norm(ee_position(app) - ee_start)))
            time.sleep(0.01)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    accepted = master.counts_now()["accepted"]
    attack(master, streamer.client.stream, 100_000)
    sampling.set()
    sampler.join(5.0)
    counts = master.counts_now()
    print(f"[flood] EE moved at most {1e3 * max(moved):.2e} mm over {len(moved)} samples; "
          f"counts {dict(sorted(counts.items()))}")
    assert max(moved) < 1e-9  # round-off: the master holds still
    assert np.array_equal(app.console.targets[0].translation, target)
    assert counts.get("releases", 0) == 0 and master.master == bound
    assert app.devices[0].state == FeedbackState.FOLLOWING
    assert counts["accepted"] > accepted  # the master kept streaming through it
    intruding = sum(counts.get(reason, 0) for reason in ("foreign", "unauthenticated",
                                                           "replayed", "version"))
    # every datagram of the flood counted: read (within the receiver's budget) and refused,
    # or dropped by the system from the shared socket's full queue (never the master's)
    assert counts["foreign"] + counts.get("overflow", 0) >= 50_000 and intruding <= 100_001
    assert 0 <= counts.get("lost", 0) <= counts["accepted"]  # bounded, never negative
    assert "refusing datagrams not from the master" in device_words(
        {"source": master, "name": master.name, "reason": "following", "wrench": np.zeros(6)},
        "tool0", None)


def test_senders_in_a_pause_of_the_master_cannot_take_it_and_it_resumes(console):
    app, master, streamer = console
    bound, target = master.master, app.console.targets[0].translation.copy()
    ee_start = ee_position(app)
    streamer.running.clear()  # the master pauses: the watchdog releases it
    wait_for(lambda: app.devices[0].state == FeedbackState.HELD, "the watchdog")
    accepted = master.counts_now()["accepted"]
    attack(master, streamer.client.stream, 20_000)
    counts = master.counts_now()
    moved = float(np.linalg.norm(ee_position(app) - ee_start))
    print(f"[pause] EE moved {1e3 * moved:.2e} mm; counts {dict(sorted(counts.items()))}")
    assert counts["accepted"] == accepted and master.master == bound
    assert moved < 1e-6 and np.linalg.norm(app.console.targets[0].translation - target) < 1e-6
    assert (counts["unauthenticated"] + counts["foreign"] + counts["version"]
            + counts.get("overflow", 0)) >= 10_000
    streamer.running.set()  # the master resumes its own stream, and is followed
    wait_for(lambda: app.devices[0].state == FeedbackState.FOLLOWING, "the master to resume")
    assert master.master == bound and master.counts_now().get("lost", 0) <= 10


def pose_from(master: UdpMaster, sequence: int, device_time: float, arrival: float,
              sender=("127.0.0.1", 5000), key: bytes = KEY, stream: int = 1,
              launch: int | None = None) -> None:
    """A command from ``sender`` for ``launch`` (by default the master's own)."""
    master.handle(encode_command("pose", HOME, sequence, device_time, key=key, stream=stream,
                                 launch=master.launch if launch is None else launch),
                  sender, arrival)


def test_forged_numbers_from_the_master_s_own_address_change_no_counter():
    """A spoofed source address: only the tag tells; forged numbers neither lock the
    master out nor wrap its counts."""
    master = UdpMaster(port=0, key=KEY)
    try:
        pose_from(master, 1, 0.0, 10.0)
        forged_key = bytes(32)
        pose_from(master, 2**32 - 1, 0.0, 10.001, key=forged_key)  # forged sequence
        pose_from(master, 2, -1e300, 10.002, key=forged_key)  # forged device time
        spoilt = bytearray(encode_command("pose", HOME, 3, 0.003, key=KEY, stream=1,
                                          launch=master.launch))
        spoilt[8:12] = struct.pack("<I", 2**32 - 1)  # the master's datagram, its number changed
        master.handle(bytes(spoilt), ("127.0.0.1", 5000), 10.003)
        pose_from(master, 2, 0.002, 10.004)  # the master goes on: taken
        counts = master.counts_now()
        assert (counts["accepted"], counts["unauthenticated"], counts.get("lost", 0)) == (2, 3, 0)
        # the key holder itself: a jump beyond the window is refused, not counted lost
        pose_from(master, 2**32 - 1, 0.005, 10.005)
        pose_from(master, 3, 0.006, 10.006)
        counts = master.counts_now()
        assert (counts["accepted"], counts["out_of_order"], counts.get("lost", 0)) == (3, 1, 0)
        pose_from(master, 5, -0.5, 10.007)  # stale (0.5 s late against the offset)...
        pose_from(master, 4, 0.008, 10.008)  # ...then one in order: lost never negative
        assert master.counts_now().get("lost", 0) == 0
        assert master.counts_now()["stale"] == 1
    finally:
        master.close()


def test_an_old_protocol_master_is_refused_by_name():
    master = UdpMaster(port=0, key=KEY)
    try:
        old = struct.pack("<4sBBBBId7d", b"CJMI", 1, 1, 0, 0, 1, 0.0, 0, 0, 0, 1, 0, 0, 0)
        master.handle(old, ("127.0.0.1", 5000), 1.0)
        body = struct.pack("<4sBBBBId7dQ", b"CJMI", 2, 1, 0, 0, 1, 0.0, 0, 0, 0, 1, 0, 0, 0, 1)
        version_2 = body + hmac.digest(KEY, body, "sha256")[:TAG_SIZE]  # a v2 master's, keyed
        master.handle(version_2, ("127.0.0.1", 5000), 1.0)
        assert master.counts_now()["version"] == 2 and master.take() is None
        assert master.master is None
        assert "old-protocol master is refused" in master.intrusions()
        with pytest.raises(PacketError, match="protocol version 2 master: this is version 3"):
            decode_command(version_2, 0, KEY)
    finally:
        master.close()


# -- a recording from another launch (a key file kept across launches) ------------------------


def test_a_recording_from_an_earlier_launch_is_refused_at_the_next_and_counted():
    """Launch A accepts a master's commands; the same key in launch B (a key file kept):
    the recording of them, replayed first, binds nothing and moves nothing, each counted
    ``other_launch`` and answered with B's launch (useless without the key); then the real
    master, learning B's launch from that answer, is taken."""
    recording = [encode_command("pose", HOME, s, 0.001 * s, key=KEY, stream=11, launch=0)
                 for s in range(1, 3)]
    launch_a = UdpMaster(port=0, key=KEY)
    try:
        recording += [encode_command("pose", HOME, s, 0.001 * s, key=KEY, stream=11,
                                     launch=launch_a.launch) for s in range(3, 203)]
        for k, datagram in enumerate(recording):
            launch_a.handle(datagram, ("127.0.0.1", 5000), 10.0 + 0.001 * k)
        counts = launch_a.counts_now()
        assert (counts["hello"], counts["accepted"]) == (2, 200)  # what launch A took
    finally:
        launch_a.close()
    launch_b = UdpMaster(port=0, key=KEY)
    assert launch_b.launch != launch_a.launch
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # the replayer's address:
    listener.bind(("127.0.0.1", 0))  # what it is answered
    try:
        for k, datagram in enumerate(recording):
            launch_b.handle(datagram, listener.getsockname(), 20.0 + 0.001 * k)
        counts = launch_b.counts_now()
        assert (counts.get("accepted", 0), counts["other_launch"], counts["hello"]) == (0, 200, 2)
        assert launch_b.master is None and launch_b.take() is None
        assert "200 other_launch" in launch_b.intrusions()
        answer = decode_feedback(listener.recv(200), KEY)
        assert answer.launch == launch_b.launch and answer.state == FeedbackState.HELD
        # the real master: its first command is a hello, answered; then it is taken
        launch_b.start()
        with MasterClient(launch_b.port, key=KEY) as client:
            wait_for(lambda: (client.send_pose((0.0, 0.0, 0.0)), client.feedback(),
                              launch_b.counts_now().get("accepted", 0))[-1] > 0, "the master")
            assert client.launch == launch_b.launch and launch_b.master is not None
    finally:
        listener.close()
        launch_b.close()


def test_a_master_that_outlives_a_launch_carries_on_with_the_next_and_no_older_feedback_moves_it():
    first = UdpMaster(port=0, key=KEY)
    first.start()
    port = first.port
    client = MasterClient(port, key=KEY)
    try:
        wait_for(lambda: (client.send_pose((0.0, 0.0, 0.0)), client.feedback(),
                          first.counts_now().get("accepted", 0))[-1] > 0, "launch A")
        old_feedback = encode_feedback(Feedback(FeedbackState.FOLLOWING, 0, 1, 0, 0.0,
                                                (0.0,) * 6, 0.0, launch=first.launch), KEY)
        first.close()
        second = UdpMaster(port=port, key=KEY)  # the page restarted, the same key file
        second.start()
        try:
            wait_for(lambda: (client.send_pose((0.0, 0.0, 0.0)), client.feedback(),
                              second.counts_now().get("accepted", 0))[-1] > 0, "launch B")
            assert client.launch == second.launch
            assert 1 <= second.counts_now()["other_launch"] <= 20  # a round trip's worth
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as replayer:
                replayer.sendto(old_feedback, client._socket.getsockname())
            time.sleep(0.05)
            client.feedback()
            assert client.launch == second.launch  # an answer to a command sent long ago
        finally:
            second.close()
    finally:
        client.close()


def test_beyond_loopback_a_key_is_required_and_key_files_are_checked(tmp_path):
    with pytest.raises(ValueError, match="needs a key"):
        UdpMaster(port=0, host="0.0.0.0")
    good = tmp_path / "key"
    good.write_text(KEY.hex() + "\n")
    assert read_key_file(good) == KEY
    for content, message in [("zz" * 32, "hexadecimal"), ("ab" * 8 + "a", "hexadecimal"),
                             ("ab" * 4, "16 to 64 bytes"), ("ab" * 600, "longer than")]:
        (tmp_path / "bad").write_text(content)
        with pytest.raises(ValueError, match=message):
            read_key_file(tmp_path / "bad")
    with pytest.raises(ValueError, match="not a regular file"):
        read_key_file("/dev/zero")
    with pytest.raises(ValueError, match="No such file"):
        read_key_file(tmp_path / "missing")


def test_teleop_web_refuses_a_bad_key_file_in_one_line(tmp_path, capsys):
    from browser_helpers import free_port

    from web import cli as web_cli

    (tmp_path / "key").write_text("not a key")
    assert web_cli.main(["--port", str(free_port()), "--input", "udp:0",
                         "--input-key", str(tmp_path / "key")]) == 2
    assert web_cli.main(["--port", str(free_port()), "--input-key",
                         str(tmp_path / "key")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "key file" in err[0] and "needs an --input udp" in err[1], err


def test_the_tag_is_hmac_sha256_of_the_rest_truncated():
    import hmac

    datagram = encode_command("pose", HOME, 1, 0.0, key=KEY, stream=3)
    body = datagram[:COMMAND_FORMAT.size]
    assert datagram[COMMAND_FORMAT.size:] == hmac.digest(KEY, body, "sha256")[:TAG_SIZE]
    assert len(datagram) == 108
