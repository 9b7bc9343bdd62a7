"""The network master: commands over UDP in, feedback out (docs/design.md section 19.2,
the protocol in :mod:`teleop.inputs.protocol`).

A thread receives; each datagram is decoded and checked, then either offered to the
control tick or dropped and counted by reason. Besides a bad datagram
(:func:`~teleop.inputs.protocol.decode_command`):

* ``out_of_order``: a sequence number not above the newest accepted (a replay, a
  reordered datagram); a gap in the numbers counts the ones that never arrived as
  ``lost``;
* ``stale``: a command that spent more than ``max_age`` in transit, measured against the
  fastest transit seen (``arrival - device_time`` at its minimum, which rises by
  :data:`OFFSET_DRIFT` per second so that clocks drifting apart are followed: the two
  clocks' offset); ``device_time`` must not go back;
* ``foreign``: from another address than the master's while the master is live (the
  first sender becomes the master; after a silence that released it, the next sender).

After a silence (:meth:`release`) the next command starts a new stream: any sequence
number and clock are taken. Every accepted command is answered with the newest
feedback, to the sender, at the master's rate.
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np

from .protocol import (Feedback, FeedbackState, PacketError, decode_command,
                       encode_feedback)
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


class UdpMaster(InputSource):
    """A network master on ``host:port`` (UDP) driving EE ``ee``.

    host : the address to bind (loopback by default: whoever can send to it moves the
        robot).
    max_age : a command older than this on arrival, against the fastest transit seen,
        is dropped as ``stale`` (s).
    """

    renders_feedback = True

    def __init__(self, port: int, host: str = "127.0.0.1", ee: int = 0,
                 max_age: float = 0.1) -> None:
        super().__init__(f"udp:{port}", ee)
        self.host = host
        self.max_age = float(max_age)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._socket = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._socket.bind((host, port))
        except OSError as error:
            self._socket.close()
            raise ValueError(f"cannot receive the master on udp {host}:{port}: "
                             f"{error.strerror or error}") from None
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
        self._socket.settimeout(POLL_INTERVAL)
        self.port = self._socket.getsockname()[1]
        self.name = f"udp:{self.port}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name=f"input {self.name}",
                                        daemon=True)
        self._master: tuple | None = None  # the sender's address
        self._newest_sequence: int | None = None
        self._clock_offset: float | None = None  # min over accepted of arrival - device_time
        self._stale_in_gap = 0  # stale commands since the newest accepted
        self._offset_time = 0.0  # when the offset was last updated
        self._feedback = Feedback(FeedbackState.HELD, ee, 0, 0, 0.0, (0.0,) * 6, float("nan"))

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(1.0)
        self._socket.close()

    def release(self) -> None:
        """The watchdog released this master: the next command, from whichever address,
        starts a new stream."""
        with self._lock:
            self._master = None
            self._newest_sequence = None
            self._clock_offset = None
            self._stale_in_gap = 0

    def set_feedback(self, wrench: np.ndarray, state: FeedbackState,
                     port_force_measured: bool) -> None:
        self._feedback = Feedback(state, self.ee, 0, self.applied_sequence, 0.0,
                                  tuple(float(w) for w in wrench), self.last_latency,
                                  port_force_measured)

    def _receive(self) -> None:
        receive, clock = self._socket.recvfrom, time.perf_counter
        while not self._stop.is_set():
            try:
                datagram, sender = receive(RECEIVE_SIZE)
            except TimeoutError:
                continue
            except ConnectionRefusedError:  # an ICMP error of a previous reply: the master
                continue  # is gone, the watchdog will say so
            except OSError as error:  # closed under us, or a broken socket: stop receiving
                if not self._stop.is_set():
                    self.problem = f"receiving stopped: {error}"
                return
            self.handle(datagram, sender, clock())

    def handle(self, datagram: bytes, sender: tuple, arrival: float) -> None:
        """One datagram from ``sender`` arrived at ``arrival`` (``perf_counter``): offered
        to the control tick and answered, or dropped and counted."""
        self.count("received")
        try:
            command = decode_command(datagram, self.ee)
        except PacketError as error:
            self.count(error.reason)
            return
        with self._lock:
            reason = self._refusal(command.sequence, command.device_time, sender, arrival)
            if reason:
                self.counts[reason] += 1
                return
        self.offer(InputSample(command.kind, command.values, command.buttons,
                               command.sequence, arrival))
        feedback = self._feedback
        reply = Feedback(feedback.state, self.ee, command.sequence, feedback.applied,
                         command.device_time, feedback.wrench, feedback.latency,
                         feedback.port_force_measured)
        try:
            self._socket.sendto(encode_feedback(reply), sender)
        except OSError:
            self.count("feedback_not_sent")

    def _refusal(self, sequence: int, device_time: float, sender: tuple,
                 arrival: float) -> str:
        """Why a valid command cannot be taken ("" when it can; caller holds the lock),
        updating the stream's state when it can."""
        if self._master is not None and sender != self._master:
            return "foreign"
        newest = self._newest_sequence
        if newest is not None and sequence <= newest:
            return "out_of_order"
        transit = arrival - device_time
        if self._clock_offset is not None and transit - self._clock_offset > self.max_age:
            self._stale_in_gap += 1  # it arrived: not lost
            return "stale"
        if newest is not None:
            self.counts["lost"] += sequence - newest - 1 - self._stale_in_gap
        self._stale_in_gap = 0
        if self._clock_offset is not None:  # the minimum forgets slowly: the clocks drift
            self._clock_offset = min(transit, self._clock_offset
                                     + OFFSET_DRIFT * (arrival - self._offset_time))
        else:
            self._clock_offset = transit
        self._offset_time = arrival
        self._master = sender
        self._newest_sequence = sequence
        return ""

