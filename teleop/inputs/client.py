"""The master's side of the protocol (:mod:`teleop.inputs.protocol`): what a program
driving a haptic device or a script sends, and the feedback it reads back."""

from __future__ import annotations

import socket
import time

from .protocol import (FEEDBACK_SIZE, Feedback, PacketError, as_key, decode_feedback,
                       encode_command, new_stream)


class MasterClient:
    """Sends commands to ``teleop web --input udp:PORT`` (or a
    :class:`~teleop.inputs.UdpMaster`) and reads its feedback.

    key : the key ``teleop web`` printed or read from ``--input-key`` (bytes or hex
        text); every command is tagged with it, and a feedback not tagged with it is
        ignored (counted in :attr:`refused`).

    Each command gets the next sequence number, the time of ``clock`` (s), the client's
    :attr:`stream` (drawn at random: a new client is a new stream) and the receiver's
    :attr:`launch` as its feedback announced it; the feedback answering it arrives on the
    same socket (:meth:`feedback`). Until a feedback has announced the launch, the
    commands are hellos: answered, never applied (one round trip).
    """

    def __init__(self, port: int, key: bytes | str, host: str = "127.0.0.1", ee: int = 0,
                 clock=time.perf_counter) -> None:
        self.key = as_key(key)
        self.address = (host, int(port))
        self.ee = ee
        self.clock = clock
        self.sequence = 0
        self.stream = new_stream()
        #: the receiver's launch, from its feedback (0 before one arrived)
        self.launch = 0
        self._launch_since = 1  # the first sequence number sent with :attr:`launch`
        self._socket = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET,
                                     socket.SOCK_DGRAM)
        self._socket.setblocking(False)
        self.received: list[Feedback] = []
        #: datagrams read that were not a feedback tagged with the key
        self.refused = 0

    def close(self) -> None:
        self._socket.close()

    def __enter__(self) -> "MasterClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def send(self, kind: str, values, buttons: int = 0) -> int:
        """One command (``kind`` "pose": x y z qw qx qy qz; "twist": vx vy vz wx wy wz);
        returns its sequence number."""
        self.sequence += 1
        self._socket.sendto(encode_command(kind, values, self.sequence, self.clock(), self.ee,
                                           buttons, key=self.key, stream=self.stream,
                                           launch=self.launch), self.address)
        return self.sequence

    def send_pose(self, position, wxyz=(1.0, 0.0, 0.0, 0.0), buttons: int = 0) -> int:
        return self.send("pose", [*position, *wxyz], buttons)

    def send_twist(self, linear, angular=(0.0, 0.0, 0.0), buttons: int = 0) -> int:
        return self.send("twist", [*linear, *angular], buttons)

    def feedback(self) -> Feedback | None:
        """Reads every feedback waiting (kept in :attr:`received`); the newest, or None.
        A feedback that answers a command sent since the launch last changed and
        announces another launch (the receiver restarted, or the first answer) gives the
        commands from now on that launch; an older one (replayed) does not."""
        newest = None
        while True:
            try:
                datagram = self._socket.recv(FEEDBACK_SIZE + 1)
            except (BlockingIOError, InterruptedError):
                return newest
            except ConnectionRefusedError:  # nothing listens (an earlier command's ICMP error)
                continue
            try:
                newest = decode_feedback(datagram, self.key)
            except PacketError:
                self.refused += 1
                continue
            self.received.append(newest)
            if newest.launch != self.launch and newest.sequence >= self._launch_since:
                self.launch, self._launch_since = newest.launch, self.sequence + 1
