"""What one browser connection may cost the server: its messages read at a bounded rate,
a gizmo's drags coalesced to the newest, and handed to viser at a bounded rate.

viser handles every message a page sends on its event loop and runs each gizmo callback
on a pool of threads; all of it shares the interpreter with the control thread. A page,
or a script holding the token, sending drags as fast as its socket takes them (10,000 in
0.2 s) would hold the control loop at 0.6-0.7 of its rate for seconds (docs/inputs.md,
"Floods"). So each connection's messages pass through a :class:`PacedMessages`:

* a **pump** reads them from the connection at most :data:`READ_RATE` a second (bursts of
  :data:`READ_BURST`); beyond that it stops reading, the connection's buffers fill and
  TCP slows the sender down: the flood waits in the sender, not here;
* a read message joins the queue of messages waiting for viser, except that a gizmo's
  drag (``TransformControlsUpdateMessage``) or a camera report (``ViewerCameraMessage``)
  right behind one of the same gizmo, or behind another camera report, **replaces** it:
  the newest wins, and nothing passes anything else (a drag's end stays after its last
  move);
* viser is handed them at most :data:`DELIVER_RATE` a second (bursts of
  :data:`DELIVER_BURST`); at most :data:`MAX_WAITING` wait, then the pump waits too.

The server's connections together are held to :data:`SERVER_SHARE` times those rates (a
page opened in many tabs, or a script opening many connections with the token, cannot
multiply them).

A browser dragging a gizmo sends one drag per frame (60-240 a second) and a camera report
per frame while the view moves: below the rates, so an operator's drags pass untouched
and at once. (The inbox, web/inbox.py, coalesces again what reaches the app.)
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from collections.abc import Awaitable, Callable

import msgspec
import viser

#: messages read from one connection per second, and the burst read at once
READ_RATE = 600.0
READ_BURST = 100
#: messages handed to viser per second for one connection, and the burst
DELIVER_RATE = 150.0
DELIVER_BURST = 50
#: messages read and waiting for viser, per connection; the pump waits beyond
MAX_WAITING = 64
#: every connection of a server together: this many times one connection's rates
SERVER_SHARE = 4


class _Head(msgspec.Struct):
    """The fields of a message that say whether it coalesces (the rest is not decoded)."""

    type: str = ""
    name: str = ""
    owner: str = ""


_HEAD = msgspec.msgpack.Decoder(_Head)
#: message types whose newest replaces the one right before it with the same key
COALESCED = frozenset({"TransformControlsUpdateMessage", "ViewerCameraMessage"})


def coalescing_key(message: bytes) -> tuple[str, str, str] | None:
    """What a message replaces the one before it for (its type, gizmo, owner), or None:
    it is kept as it is (a click, a drag's start or end, anything not decodable)."""
    try:
        head = _HEAD.decode(message)
    except (msgspec.DecodeError, TypeError):
        return None
    return (head.type, head.name, head.owner) if head.type in COALESCED else None


class Bucket:
    """A token bucket: :meth:`take` waits until one of ``burst`` tokens, refilled at
    ``rate`` a second, is there."""

    def __init__(self, rate: float, burst: int, clock: Callable[[], float] = time.monotonic):
        self.rate, self.burst, self.clock = rate, burst, clock
        self.tokens = float(burst)
        self.time = clock()

    def wait(self) -> float:
        """Take a token and return 0, or return how long until one is there (s)."""
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.time) * self.rate)
        self.time = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return 0.0
        return (1.0 - self.tokens) / self.rate

    async def take(self) -> None:
        while (delay := self.wait()) > 0.0:
            await asyncio.sleep(delay)


class Tally:
    """Messages read, replaced by a newer one, and handed on, over connections."""

    def __init__(self) -> None:
        self.read = self.coalesced = self.delivered = 0


class PacedMessages:
    """One connection's messages, read by a pump at a bounded rate, coalesced, and
    handed on at a bounded rate (see the module's text). ``receive`` is the connection's
    own ``recv``; :meth:`recv` replaces it. ``tally`` counts what it does (with others')."""

    def __init__(self, receive: Callable[[], Awaitable[bytes | str]], tally: Tally | None = None,
                 read_rate: float = READ_RATE, read_burst: int = READ_BURST,
                 deliver_rate: float = DELIVER_RATE, deliver_burst: int = DELIVER_BURST,
                 max_waiting: int = MAX_WAITING, shared: tuple[Bucket, Bucket] | None = None
                 ) -> None:
        self._receive = receive
        self.tally = Tally() if tally is None else tally
        self.reading = Bucket(read_rate, read_burst)
        self.delivering = Bucket(deliver_rate, deliver_burst)
        #: the buckets every connection of the server draws from too (reading, delivering)
        self.shared = shared
        self.max_waiting = max_waiting
        self._waiting: deque[tuple[tuple | None, bytes | str]] = deque()
        self._arrived = asyncio.Event()  # the pump queued a message, or stopped
        self._room = asyncio.Event()  # recv took one
        self._pump: asyncio.Task | None = None

    async def recv(self, decode: bool | None = None) -> bytes | str:
        """The next message for viser (``decode`` is ignored: viser reads bytes); the
        connection's own error (it closed) once nothing waits."""
        if self._pump is None:
            self._pump = asyncio.get_running_loop().create_task(self._run())
            self._pump.add_done_callback(lambda task: task.cancelled() or task.exception())
        while not self._waiting:
            if self._pump.done():
                self._pump.result()  # the connection's error: it closed
                raise ConnectionError("the connection's reader stopped")
            self._arrived.clear()
            await self._arrived.wait()
        await self.delivering.take()  # meanwhile a newer drag may replace the first
        if self.shared is not None:
            await self.shared[1].take()
        _, message = self._waiting.popleft()
        self.tally.delivered += 1
        self._room.set()
        return message

    async def _run(self) -> None:
        try:
            while True:
                await self.reading.take()
                if self.shared is not None:
                    await self.shared[0].take()
                while len(self._waiting) >= self.max_waiting:
                    self._room.clear()
                    await self._room.wait()
                message = await self._receive()
                self.tally.read += 1
                key = coalescing_key(message) if isinstance(message, bytes) else None
                if key is not None and self._waiting and self._waiting[-1][0] == key:
                    self._waiting[-1] = (key, message)
                    self.tally.coalesced += 1
                else:
                    self._waiting.append((key, message))
                self._arrived.set()
        finally:
            self._arrived.set()  # recv sees that the pump stopped


def pace_messages(server: viser.ViserServer) -> Tally:
    """Pace every connection of ``server`` (:class:`PacedMessages`) from its first
    message on; what they did, together, is counted in the :class:`Tally` returned."""
    websocket_server = server._websock_server
    tally = Tally()
    shared = (Bucket(SERVER_SHARE * READ_RATE, SERVER_SHARE * READ_BURST),
              Bucket(SERVER_SHARE * DELIVER_RATE, SERVER_SHARE * DELIVER_BURST))

    async def pace(connection) -> None:
        websocket = websocket_server._live_connections.get(connection.client_id)
        if websocket is not None:
            websocket.recv = PacedMessages(websocket.recv, tally, shared=shared).recv

    websocket_server._client_connect_cb.insert(0, pace)
    return tally
