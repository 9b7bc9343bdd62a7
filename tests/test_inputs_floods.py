"""A flood of datagrams at the network master's port costs the receiver a bounded share
of the interpreter and never crowds out the master (docs/inputs.md, "Floods"): the
receiver reads in batches of at most a budget, the datagrams the system drops from a full
queue are counted, and the bound master's datagrams arrive on a socket of their own.
Everything here reads the sockets by hand (no receiving thread): what is asserted holds
on a loaded machine. The rates under floods are measured by docs/measure_floods.py."""

from __future__ import annotations

import socket

import pytest

from teleop.inputs import MasterClient, UdpMaster
from teleop.inputs.udp import BATCH, MASTER_BATCH

KEY = bytes(range(32))


@pytest.fixture
def master():
    receiver = UdpMaster(port=0, key=KEY)
    yield receiver
    receiver.close()


def flood(port: int, count: int) -> socket.socket:
    """``count`` malformed datagrams at ``port`` from a socket of their own (returned)."""
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for k in range(count):
        sender.sendto(k.to_bytes(4, "little") * 25, ("127.0.0.1", port))
    return sender


def drain(master: UdpMaster, sock=None) -> int:
    """Read ``sock`` (the shared socket by default) until it is empty; datagrams read."""
    total = 0
    while (read := master.receive_batch(sock, BATCH)) > 0:
        assert read <= BATCH
        total += read
    return total


def join(master: UdpMaster, client: MasterClient) -> None:
    """The client's hello, answered with the launch; then its first command, taken."""
    client.send_pose((0.0, 0.0, 0.0))
    assert drain(master) == 1 and master.counts_now()["hello"] == 1
    client.feedback()
    client.send_pose((0.0, 0.0, 0.0))
    assert drain(master) == 1 and master.master is not None


def test_datagrams_are_read_in_batches_of_at_most_the_budget(master):
    with flood(master.port, 100):
        assert [master.receive_batch(budget=BATCH) for _ in range(3)] == [BATCH] * 3
        assert master.counts_now()["malformed"] == 3 * BATCH
        assert master.receive_batch(budget=1000) == 100 - 3 * BATCH
        assert master.receive_batch(budget=1000) == 0  # nothing waits: it returns at once
        assert master.counts_now()["received"] == 100


def test_what_overflows_the_queue_is_counted_with_the_next_datagram_read(master):
    sent = 30_000  # more than the socket's queue holds (about 10,000 such datagrams)
    with flood(master.port, sent) as sender:
        read = drain(master)
        assert read < sent and "overflow" not in master.counts_now()  # not yet known
        sender.sendto(b"one more", ("127.0.0.1", master.port))
        read += drain(master)
    counts = master.counts_now()
    print(f"\n[overflow] {sent + 1} sent: {read} read, {counts['overflow']} dropped by the "
          "system from the full queue")
    assert counts["received"] == counts["malformed"] == read
    # every datagram either read or counted (the system may also drop a few on its own way
    # to the socket, before any queue of ours: never counted twice)
    assert 0 < counts["overflow"] and read + counts["overflow"] <= sent + 1
    assert read + counts["overflow"] >= 0.9 * (sent + 1)


def test_a_flood_fills_the_shared_queue_never_the_master_s(master):
    with MasterClient(master.port, key=KEY) as client:
        join(master, client)  # bound: its own socket
        assert master.master_socket is not None
        with flood(master.port, 30_000):  # the shared queue overflows
            sent = [client.send_pose((0.0, 0.0, 0.0)) for _ in range(MASTER_BATCH)]
            assert master.receive_batch(master.master_socket, MASTER_BATCH) == MASTER_BATCH
            assert master.take().sequence == sent[-1]
            assert master.receive_batch(master.master_socket, MASTER_BATCH) == 0
            counts = master.counts_now()
            assert counts["accepted"] == 1 + MASTER_BATCH and "foreign" not in counts
            assert master.receive_batch(budget=BATCH) == BATCH  # the flood, apart
            assert master.counts_now()["foreign"] == BATCH


def test_no_other_socket_can_bind_the_port_before_or_after_the_master_binds(master):
    for reuse in (0, 1):
        other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, reuse)
        with other, pytest.raises(OSError):
            other.bind(("127.0.0.1", master.port))
    with MasterClient(master.port, key=KEY) as client:
        join(master, client)
        assert master.master_socket is not None
        for reuse in (0, 1):
            other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, reuse)
            with other, pytest.raises(OSError):
                other.bind(("127.0.0.1", master.port))
