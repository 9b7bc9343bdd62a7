"""What one browser connection may cost the server (web/pacing.py): its messages are read
and handed to viser at bounded rates, a gizmo's drags coalesced to the newest, in order.

The pacer's own behaviour is checked on a scripted connection (a receive that answers at
once, so what is read before each hand-over is fixed); the token bucket on a clock the
test moves; and on a real viser server, a raw websocket client's 2,000 drags: the newest
reaches the gizmo's callback, and the callbacks stay within the bucket's bound over the
time they took, whatever the machine's load."""

from __future__ import annotations

import asyncio
import math
import threading
import time

import msgspec
import numpy as np
import pytest
import viser
from browser_helpers import free_port
from viser._messages import (TransformControlsDragEndMessage, TransformControlsUpdateMessage,
                             ViewerCameraMessage)
from websockets.sync.client import connect

from web.pacing import (DELIVER_BURST, DELIVER_RATE, Bucket, PacedMessages, Tally,
                        coalescing_key, pace_messages)

WXYZ = (1.0, 0.0, 0.0, 0.0)


def wire(message) -> bytes:
    """``message`` as a browser sends it."""
    return msgspec.msgpack.encode(message.as_serializable_dict())


def drag(name: str, x: float) -> bytes:
    return wire(TransformControlsUpdateMessage(name, WXYZ, (x, 0.0, 0.0)))


def camera(x: float) -> bytes:
    return wire(ViewerCameraMessage(WXYZ, (x, 0.0, 1.0), 1.0, 0.01, 100.0, 600, 800,
                                    (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)))


class Closed(Exception):
    """The scripted connection's end."""


def scripted(messages: list[bytes]):
    """A connection's ``recv`` that answers each message at once, then :class:`Closed`."""
    queue = list(messages)

    async def receive() -> bytes:
        if not queue:
            raise Closed
        return queue.pop(0)
    return receive


async def everything(paced: PacedMessages) -> list[bytes]:
    out = []
    try:
        while True:
            out.append(await paced.recv())
    except Closed:
        return out


def test_consecutive_drags_of_one_gizmo_coalesce_to_the_newest_and_nothing_passes_another():
    end = wire(TransformControlsDragEndMessage("/gizmo"))
    click = b"\x81\xa4type\xa5Click"  # not a drag: kept as it is
    sent = ([camera(0.0), camera(1.0)] + [drag("/gizmo", 0.01 * k) for k in range(100)]
            + [end] + [drag("/other", k) for k in range(30)] + [click, b"not msgpack"])
    tally = Tally()
    paced = PacedMessages(scripted(sent), tally, read_rate=1e9, read_burst=10_000,
                          deliver_rate=1e9, deliver_burst=10_000, max_waiting=1000)
    received = asyncio.run(everything(paced))
    assert received == [camera(1.0), drag("/gizmo", 0.99), end, drag("/other", 29), click,
                        b"not msgpack"]
    assert (tally.read, tally.coalesced, tally.delivered) == (len(sent), len(sent) - 6, 6)
    assert coalescing_key(drag("/a", 0.0)) == ("TransformControlsUpdateMessage", "/a", "")
    assert coalescing_key(end) is None and coalescing_key(b"\xff\x00") is None


def test_the_pump_stops_reading_when_enough_messages_wait():
    clicks = [f"click {k}".encode() for k in range(200)]
    tally = Tally()
    paced = PacedMessages(scripted(clicks), tally, read_rate=1e9, read_burst=10_000,
                          deliver_rate=1e9, deliver_burst=10_000, max_waiting=64)

    async def two() -> tuple[bytes, int, bytes, int]:
        first = await paced.recv()
        await asyncio.sleep(0)  # the pump runs until 64 wait
        read = tally.read
        second = await paced.recv()
        await asyncio.sleep(0)
        return first, read, second, tally.read

    first, read, second, then = asyncio.run(two())
    assert (first, second) == (clicks[0], clicks[1])
    assert read == 65 and then == 66  # one more read per one handed on


def test_connections_sharing_the_server_s_bucket_cannot_multiply_it():
    """Three connections, each free on its own, drawing on one server bucket of 5 tokens
    that refills once in 1e6 s: 5 messages handed on in all, then none."""
    shared = (Bucket(1e9, 10_000), Bucket(1e-6, 5))
    connections = [PacedMessages(scripted([f"{k} {i}".encode() for i in range(10)]),
                                 read_rate=1e9, read_burst=10_000, deliver_rate=1e9,
                                 deliver_burst=10_000, shared=shared) for k in range(3)]

    async def race() -> list[bytes]:
        handed: list[bytes] = []

        async def drain(paced: PacedMessages) -> None:
            while True:
                handed.append(await paced.recv())

        tasks = [asyncio.ensure_future(drain(paced)) for paced in connections]
        await asyncio.sleep(0.3)  # the 6th token is a million seconds away
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        return handed

    assert len(asyncio.run(race())) == 5


def test_a_bucket_gives_its_burst_then_one_token_per_period():
    now = [0.0]
    bucket = Bucket(rate=100.0, burst=3, clock=lambda: now[0])
    assert [bucket.wait() for _ in range(3)] == [0.0, 0.0, 0.0]
    assert math.isclose(bucket.wait(), 0.01)
    now[0] = 0.004
    assert math.isclose(bucket.wait(), 0.006)
    now[0] = 0.010
    assert bucket.wait() == 0.0 and bucket.wait() > 0.0
    now[0] = 10.0  # a long pause refills to the burst, not beyond
    assert [bucket.wait() for _ in range(4)][-1] > 0.0


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    server.tally = pace_messages(server)
    yield server
    server.stop()


@pytest.mark.slow
def test_a_flood_of_drags_reaches_the_app_paced_and_the_newest_last(server):
    gizmo = server.scene.add_transform_controls("/gizmo")
    seen: list[float] = []
    lock = threading.Lock()

    @gizmo.on_update
    def _(event) -> None:
        with lock:
            seen.append(float(event.target.position[0]))

    count = 2000
    url = f"ws://127.0.0.1:{server.get_port()}/"
    with connect(url, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=30,
                 max_queue=None) as socket:
        start = time.monotonic()
        socket.send(camera(2.0))  # viser counts a browser from its first camera report
        for k in range(count):
            socket.send(drag("/gizmo", 1e-3 * (k + 1)))
        deadline = time.monotonic() + 120.0
        newest = 1e-3 * count
        while gizmo.position[0] != pytest.approx(newest) or len(seen) < server.tally.delivered - 1:
            assert time.monotonic() < deadline, "the newest drag never arrived"
            time.sleep(0.01)
        end = time.monotonic()
    with lock:
        positions = np.array(seen)
    tally = server.tally
    print(f"\n[pacing] {count} drags: {tally.read} messages read, {tally.coalesced} coalesced, "
          f"{tally.delivered} handed to viser, {len(seen)} callbacks in {end - start:.2f} s")
    assert tally.read == count + 1 and tally.delivered + tally.coalesced == tally.read
    assert len(seen) == tally.delivered - 1  # every drag handed on ran the callback
    assert positions.max() == pytest.approx(newest)  # the newest is never coalesced away
    # every hand-over happened between the first send and the newest's arrival: the
    # bucket's bound over that time
    assert tally.delivered <= DELIVER_BURST + DELIVER_RATE * (end - start)
