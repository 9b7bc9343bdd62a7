"""The network master: commands over UDP in, feedback out (docs/design.md section 19.2,
the protocol in :mod:`teleop.inputs.protocol`).

A thread receives; each datagram is checked, then either offered to the control tick or
dropped and counted by reason. The master is **bound** to the first sender whose command
authenticates (its address and its stream number); from then on:

* ``foreign``: from another address while the bound master is live, counted before it
  is even decoded (a flood costs little); after a silence that released it, from another
  address with the bound stream;
* a bad datagram (:func:`~teleop.inputs.protocol.decode_command`): ``version`` (another
  protocol version), ``malformed``, ``unauthenticated`` (its tag is not the key's), ...;
* the **launch**: every command carries the receiver's launch number (:attr:`launch`,
  drawn when it starts, announced in every feedback) inside what the tag covers. One with
  0 is a master's ``hello`` (it has not heard the number yet), one with another number
  ``other_launch`` (a recording from an earlier launch with the same key, or a master that
  outlived one): neither is applied, both are answered with a feedback that announces the
  number, so a live master carries on after one round trip, and a recording never binds;
* ``out_of_order``: a sequence number not above the newest accepted (a replay, a
  reordered datagram), or more than :data:`SEQUENCE_WINDOW` above it while the master is
  live; a gap in the numbers counts the ones that never arrived as ``lost``;
* ``replayed``: a stream the master has already left (a recording of it);
* ``stale``: a command that spent more than ``max_age`` in transit, measured against the
  fastest transit seen (``arrival - device_time`` at its minimum, which rises by
  :data:`OFFSET_DRIFT` per second so that clocks drifting apart are followed: the two
  clocks' offset); ``device_time`` must not go back.

The watchdog's :meth:`release` keeps the binding: the silent master may resume (its
stream, its next sequence numbers), and only a new stream that authenticates (a
restarted master, who holds the key) may take its place. Every accepted command is
answered with the newest feedback, tagged, to its sender, at the master's rate.

**Floods** (docs/inputs.md, "Floods"). Once bound, the master gets a socket of its own:
one on the same port, connected to its address, so that the system hands it the master's
datagrams and only those (``SO_REUSEPORT``; Linux gives a connected socket of the group
every datagram of its address pair). A flood from anywhere else then fills the shared
socket's queue, never the master's. The receiving thread reads each socket in bounded
batches, at most :data:`BATCH` datagrams per :data:`SLICE` (and :data:`MASTER_BATCH`
from the master's), so that however fast datagrams arrive it takes a bounded share of the
interpreter from the control thread; what the system then drops from a full queue is
counted (``overflow``, from the socket's drop counter ``SO_RXQ_OVFL``).
"""

from __future__ import annotations

import ipaddress
import select
import socket
import threading
import time
from collections import OrderedDict

import numpy as np

from .protocol import (Command, Feedback, FeedbackState, PacketError, as_key, decode_command,
                       encode_feedback, new_key, new_launch)
from .source import InputSample, InputSource

#: the largest datagram read: a longer one is read whole and refused as malformed
RECEIVE_SIZE = 2048
#: the receiving thread wakes this often to see whether it should stop (s)
POLL_INTERVAL = 0.05
#: the socket's receive buffer asked for (bytes; the system may cap it): commands that
#: arrive while the receiving thread waits for the interpreter queue here, not lost
RECEIVE_BUFFER = 1 << 22
#: how fast the clocks' offset estimate may rise (s per s): two clocks drifting apart by up
#: to 1000 ppm, or a master's clock stepping back, never make its commands all stale
OFFSET_DRIFT = 1e-3
#: a live master's next sequence number is at most this far above its newest (17 min of
#: commands at 1 kHz): the ``lost`` count of one gap is bounded by it
SEQUENCE_WINDOW = 1 << 20
#: streams a master has left, remembered so that a recording of them is refused
RETIRED_STREAMS = 4096
#: reasons that mean someone other than the master is sending (the page warns of them)
INTRUSIONS = ("foreign", "unauthenticated", "replayed", "version", "other_launch")
#: the receiving thread's budget: at most :data:`BATCH` datagrams from the shared socket
#: and :data:`MASTER_BATCH` from the master's own per :data:`SLICE` seconds (8,000 and
#: 16,000 a second: a master streams at 1 kHz); the rest waits in the socket's queue, and
#: what overflows it is counted ``overflow``
SLICE = 5e-3
BATCH = 20
MASTER_BATCH = 40
#: Linux's socket option that attaches the socket's count of dropped datagrams to each
#: datagram read (``SO_RXQ_OVFL``; Python names it on no platform)
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)
_DROP_COUNTER = socket.CMSG_SPACE(4)


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.split("%")[0]).is_loopback
    except ValueError:
        return host == "localhost"


class UdpMaster(InputSource):
    """A network master on ``host:port`` (UDP) driving EE ``ee``.

    host : the address to bind (loopback by default).
    key : the shared key (bytes or hex text, :func:`~teleop.inputs.protocol.as_key`)
        every command's tag is checked with; None draws one (:attr:`key`) on a loopback
        address, and is a ``ValueError`` on any other.
    max_age : a command older than this on arrival, against the fastest transit seen,
        is dropped as ``stale`` (s).
    """

    renders_feedback = True

    def __init__(self, port: int, host: str = "127.0.0.1", ee: int = 0,
                 max_age: float = 0.1, key: bytes | str | None = None) -> None:
        super().__init__(f"udp:{port}", ee)
        if key is None and not _is_loopback(host):
            raise ValueError(f"a network master on {host} (beyond this machine) needs a key: "
                             "give the key file the master holds")
        #: the shared key (give it to the master)
        self.key = new_key() if key is None else as_key(key)
        #: this receiver's launch number, drawn now: its feedback announces it, and a command
        #: must carry it (a recording from another launch cannot)
        self.launch = new_launch()
        self.host = host
        self.max_age = float(max_age)
        self._family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._socket = self._open_socket(port)
        self.port = self._socket.getsockname()[1]
        #: the socket the bound master's datagrams arrive on, apart from everyone else's
        #: (None before one binds, or where the system cannot give it one: then they
        #: share the port's)
        self.master_socket: socket.socket | None = None
        self._overflow: dict[socket.socket, int] = {}  # each socket's drop counter
        self.name = f"udp:{self.port}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name=f"input {self.name}",
                                        daemon=True)
        #: the bound master's address and stream (None before any command authenticated)
        self.master: tuple | None = None
        self._stream: int | None = None
        self._released = False  # the watchdog released it: it may resume, or a new stream
        self._retired: OrderedDict[int, None] = OrderedDict()  # streams the master left
        self._newest_sequence: int | None = None
        self._clock_offset: float | None = None  # min over accepted of arrival - device_time
        self._stale_in_gap = 0  # stale commands since the newest accepted
        self._offset_time = 0.0  # when the offset was last updated
        #: the address the newest intruding datagram came from, and what it was
        self.intruder: tuple | None = None
        self._feedback = Feedback(FeedbackState.HELD, ee, 0, 0, 0.0, (0.0,) * 6, float("nan"),
                                  launch=self.launch)

    def start(self) -> None:
        self._thread.start()

    def _open_socket(self, port: int, peer: tuple | None = None) -> socket.socket:
        """A socket on ``port`` of :attr:`host` counting its drops; with ``peer``, one
        sharing the port with :attr:`_socket` and connected to ``peer`` (it receives that
        address's datagrams only); ``ValueError`` when the port cannot be bound.

        The two allow sharing their port (``SO_REUSEPORT``) only while the master's is
        bound: before and after, no other socket (another receiver, another process) can
        bind the port."""
        sock = socket.socket(self._family, socket.SOCK_DGRAM)
        shared = [] if peer is None else [sock, self._socket]
        try:
            for each in shared:
                each.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            sock.bind((self.host, port))
            if peer is not None:
                sock.connect(peer)
        except OSError as error:
            sock.close()
            raise ValueError(f"cannot receive the master on udp {self.host}:{port}: "
                             f"{error.strerror or error}") from None
        finally:
            for each in shared:
                if each.fileno() >= 0:
                    each.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 0)
        sock.setblocking(False)
        return sock

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(1.0)
        self._socket.close()
        if self.master_socket is not None:
            self.master_socket.close()

    def release(self) -> None:
        """The watchdog released this master: it stays bound (it may resume its stream);
        only a new stream that authenticates may take its place."""
        with self._lock:
            self._released = True
            self._stale_in_gap = 0

    def set_feedback(self, wrench: np.ndarray, state: FeedbackState,
                     port_force_measured: bool) -> None:
        self._feedback = Feedback(state, self.ee, 0, self.applied_sequence, 0.0,
                                  tuple(float(w) for w in wrench), self.last_latency,
                                  port_force_measured, self.launch)

    def intrusions(self) -> str:
        """What the operator should know about datagrams from someone other than the
        master ("" while there were none)."""
        counts = self.counts_now()
        seen = [f"{counts[reason]} {reason}" for reason in INTRUSIONS if counts.get(reason)]
        if counts.get("overflow"):  # a flood beyond the receiver's budget
            seen.append(f"{counts['overflow']} dropped unread (the queue was full)")
        if not seen:
            return ""
        sender = self.intruder
        where = f" (the newest from {sender[0]}:{sender[1]})" if sender else ""
        old = " - an old-protocol master is refused, update it" if counts.get("version") else ""
        return f"refusing datagrams not from the master: {', '.join(seen)}{where}{old}"

    def _receive(self) -> None:
        """Wait for datagrams and read them, within each socket's budget per
        :data:`SLICE`: a socket whose budget is spent is not read again before the slice
        ends (its datagrams wait in its queue)."""
        clock = time.perf_counter
        slice_end = 0.0
        left: dict[socket.socket, int] = {}
        while not self._stop.is_set():
            now = clock()
            if now >= slice_end:
                slice_end, left = now + SLICE, {}
            budgets = {self._socket: left.get(self._socket, BATCH)}
            if self.master_socket is not None:
                budgets[self.master_socket] = left.get(self.master_socket, MASTER_BATCH)
            waiting = [sock for sock, budget in budgets.items() if budget > 0]
            try:  # a socket whose budget is spent waits for the next slice
                ready = select.select(waiting, [], [], POLL_INTERVAL if len(waiting) == len(
                    budgets) else max(0.0, slice_end - now))[0]
                for sock in ready:
                    left[sock] = budgets[sock] - self.receive_batch(sock, budgets[sock])
            except (OSError, ValueError) as error:
                if self._socket.fileno() >= 0 and not self._stop.is_set():
                    continue  # a master's socket closed as a new master bound: read on
                if not self._stop.is_set():  # closed under us, or a broken socket
                    self.problem = f"receiving stopped: {error}"
                return

    def receive_batch(self, sock: socket.socket | None = None, budget: int = BATCH) -> int:
        """Read and handle the datagrams waiting on ``sock`` (the shared socket by
        default), at most ``budget`` of them, without waiting; how many were read. Each
        read brings the socket's count of datagrams the system dropped from its full
        queue (``overflow``)."""
        sock = self._socket if sock is None else sock
        clock = time.perf_counter
        read = 0
        while read < budget:
            try:
                datagram, extra, _, sender = sock.recvmsg(RECEIVE_SIZE, _DROP_COUNTER)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:  # an ICMP error of a previous reply: the master
                continue  # is gone, the watchdog will say so
            read += 1
            if extra:
                self._count_overflow(sock, int.from_bytes(extra[0][2][:4], "little"))
            self.handle(datagram, sender, clock())
        return read

    def _count_overflow(self, sock: socket.socket, dropped: int) -> None:
        """The system's drop counter of ``sock`` is ``dropped`` (it wraps at 2^32)."""
        before = self._overflow.get(sock, 0)
        if dropped != before:
            self._overflow[sock] = dropped
            self.count("overflow", (dropped - before) % (1 << 32))

    def handle(self, datagram: bytes, sender: tuple, arrival: float) -> None:
        """One datagram from ``sender`` arrived at ``arrival`` (``perf_counter``): offered
        to the control tick and answered, or dropped and counted."""
        with self._lock:
            self.counts["received"] += 1
            if self.master is not None and not self._released and sender != self.master:
                self._intrusion("foreign", sender)
                return
        try:
            command = decode_command(datagram, self.ee, self.key)
        except PacketError as error:
            with self._lock:
                if error.reason in INTRUSIONS:
                    self._intrusion(error.reason, sender)
                else:
                    self.counts[error.reason] += 1
            return
        if command.launch != self.launch:  # a hello, or another launch's: never applied
            with self._lock:
                if command.launch == 0:
                    self.counts["hello"] += 1
                else:
                    self._intrusion("other_launch", sender)
            self._answer(command, Feedback(FeedbackState.HELD, self.ee, command.sequence, 0,
                                           command.device_time, (0.0,) * 6, float("nan"),
                                           launch=self.launch), sender)
            return
        with self._lock:
            reason = self._refusal(command.stream, command.sequence, command.device_time,
                                   sender, arrival)
            if reason:
                if reason in INTRUSIONS:
                    self._intrusion(reason, sender)
                else:
                    self.counts[reason] += 1
                return
        self.offer(InputSample(command.kind, command.values, command.buttons,
                               command.sequence, arrival))
        self._answer(command, self._feedback, sender)

    def _answer(self, command: Command, feedback: Feedback, sender: tuple) -> None:
        """Send ``feedback`` to ``sender`` as the answer to ``command``, tagged."""
        reply = Feedback(feedback.state, self.ee, command.sequence, feedback.applied,
                         command.device_time, feedback.wrench, feedback.latency,
                         feedback.port_force_measured, self.launch)
        try:
            self._socket.sendto(encode_feedback(reply, self.key), sender)
        except OSError:
            self.count("feedback_not_sent")

    def _intrusion(self, reason: str, sender: tuple) -> None:
        """Count a datagram from someone other than the master (caller holds the lock)."""
        self.counts[reason] += 1
        self.intruder = sender

    def _refusal(self, stream: int, sequence: int, device_time: float, sender: tuple,
                 arrival: float) -> str:
        """Why an authenticated, valid command cannot be taken ("" when it can; caller
        holds the lock), updating the stream's state when it can."""
        if stream in self._retired:
            return "replayed"
        resumed = self._released
        if self.master is None or (self._released and stream != self._stream):
            self._bind(sender, stream)  # the first master, or a restarted one
        elif sender != self.master:
            return "foreign"  # the bound stream from elsewhere, or another stream while live
        newest = self._newest_sequence
        if newest is not None and (sequence <= newest or (
                not resumed and sequence - newest > SEQUENCE_WINDOW)):
            return "out_of_order"
        transit = arrival - device_time
        if self._clock_offset is not None and transit - self._clock_offset > self.max_age:
            self._stale_in_gap += 1  # it arrived: not lost
            return "stale"
        if newest is not None and not resumed:  # a silence's gap is not counted lost
            self.counts["lost"] += max(0, sequence - newest - 1 - self._stale_in_gap)
        self._stale_in_gap = 0
        if self._clock_offset is not None:  # the minimum forgets slowly: the clocks drift
            self._clock_offset = min(transit, self._clock_offset
                                     + OFFSET_DRIFT * (arrival - self._offset_time))
        else:
            self._clock_offset = transit
        self._offset_time = arrival
        self._newest_sequence = sequence
        self._released = False
        return ""

    def _bind(self, sender: tuple, stream: int) -> None:
        """The master is now ``sender``'s ``stream``: a new sequence and clock (caller
        holds the lock)."""
        if self._stream is not None:
            self._retired[self._stream] = None
            while len(self._retired) > RETIRED_STREAMS:
                self._retired.popitem(last=False)
        if sender != self.master:
            self._give_socket(sender)
        self.master, self._stream = sender, stream
        self._newest_sequence = None
        self._clock_offset = None
        self._stale_in_gap = 0

    def _give_socket(self, sender: tuple) -> None:
        """The master at ``sender`` gets a socket of its own (the previous master's is
        closed); where the system refuses one, its datagrams share the port's socket
        (counted ``shared_socket``; caller holds the lock)."""
        if self.master_socket is not None:
            self.master_socket.close()
            self._overflow.pop(self.master_socket, None)
            self.master_socket = None
        try:
            self.master_socket = self._open_socket(self.port, sender[:2])
        except ValueError:
            self.counts["shared_socket"] += 1
