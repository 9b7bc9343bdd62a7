"""The network master's protocol, version 3: fixed-size little-endian UDP datagrams, each
authenticated with a shared key and bound to one launch of the receiver (docs/design.md
section 19.2; the field tables are in docs/inputs.md).

A **command** (master -> teleop, :data:`COMMAND_SIZE` bytes)::

    magic "CJMI" | version u8 | kind u8 | ee u8 | buttons u8 | sequence u32 |
    device_time f64 | values 7 x f64 | stream u64 | launch u64 | tag 16 bytes

``kind`` 1 (pose: position x y z in m, quaternion w x y z) or 2 (twist: v x y z in m/s,
w x y z in rad/s, the seventh value 0), in the device's frame (x right, y up, z towards
the operator); ``buttons`` bit 0 the clutch (held: the master moves alone), bit 1 the
mode; ``sequence`` increases by one per packet; ``device_time`` the master's clock (s);
``stream`` a random number the master draws when it starts (a restarted master is a new
stream); ``launch`` the receiver's launch number, as its feedback announced it (0 before
the master has heard one: a **hello**, answered, never applied); ``tag`` the first 16
bytes of HMAC-SHA256(key, every byte before it). A command tagged for another launch (a
recording from an earlier one, with a key file kept across launches) is refused.

A **feedback** (teleop -> master, :data:`FEEDBACK_SIZE` bytes), one per command
accepted::

    magic "CJMF" | version u8 | state u8 | ee u8 | flags u8 | sequence u32 |
    applied u32 | device_time f64 | wrench 6 x f64 | latency f64 | launch u64 |
    tag 16 bytes

``sequence`` and ``device_time`` echo the command answered (the master measures its
round trip from them); ``applied`` the newest command a robot command has used;
``wrench`` the force (N) and torque (N m) to render, in the device's frame; ``latency``
that command's arrival-to-command time (s); ``state`` :class:`FeedbackState`; ``flags``
bit 0: the wrench includes a measured port force (a physics plant); ``launch`` the
receiver's launch number (drawn at random when it starts); ``tag`` as a command's, with
the same key.

The **key**: 16 to 64 random bytes both sides hold (``teleop web`` draws 32 and prints
them in hex, or reads them from ``--input-key FILE``); :func:`as_key` reads one.
"""

from __future__ import annotations

import enum
import hmac
import math
import os
import secrets
import stat
import struct
from dataclasses import dataclass

MAGIC_COMMAND = b"CJMI"
MAGIC_FEEDBACK = b"CJMF"
VERSION = 3
#: a command without its tag (the tag follows)
COMMAND_FORMAT = struct.Struct("<4sBBBBId7dQQ")
#: a feedback without its tag
FEEDBACK_FORMAT = struct.Struct("<4sBBBBIId6ddQ")
#: bytes of HMAC-SHA256 kept as a datagram's tag
TAG_SIZE = 16
COMMAND_SIZE = COMMAND_FORMAT.size + TAG_SIZE
FEEDBACK_SIZE = FEEDBACK_FORMAT.size + TAG_SIZE
#: a key is this many bytes (``teleop web`` draws :data:`KEY_SIZE`)
KEY_SIZES = (16, 64)
KEY_SIZE = 32
#: a key file is at most this long (bytes): the key in hex, and white space
MAX_KEY_FILE = 1024
KIND_POSE, KIND_TWIST = 1, 2
KINDS = {KIND_POSE: "pose", KIND_TWIST: "twist"}
#: buttons: bit 0 the clutch (held: the master moves alone), bit 1 the mode
CLUTCH, MODE = 1, 2
BUTTON_MASK = CLUTCH | MODE
#: a master's position is within this of its origin (m); a pose farther is refused
MAX_DEVICE_POSITION = 10.0
#: a quaternion's norm must be within these (it is normalised after)
QUATERNION_NORM = (0.5, 2.0)
#: a rate command is at most this fast (m/s, rad/s) before the motion scale and the
#: loop's speed caps
MAX_DEVICE_SPEED = (10.0, 100.0)
#: flags of a feedback: the wrench includes a measured port force
PORT_FORCE_MEASURED = 1


class FeedbackState(enum.IntEnum):
    """What the teleoperation does with the master's commands."""

    FOLLOWING = 0  # its EE follows the master
    CLUTCHED = 1  # the master moves alone (its clutch button, or the console's)
    HELD = 2  # the watchdog released it after a silence: the target holds


class PacketError(ValueError):
    """A datagram that is not a valid command; ``reason`` is the counter it goes to."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def as_key(key: object) -> bytes:
    """``key`` (bytes, or hex text) as bytes, else ``ValueError`` naming the problem."""
    if isinstance(key, str):
        try:
            key = bytes.fromhex(key.strip())
        except ValueError:
            raise ValueError("a key in text is hexadecimal digits (0-9 a-f), "
                             f"{2 * KEY_SIZES[0]} to {2 * KEY_SIZES[1]} of them") from None
    if not isinstance(key, (bytes, bytearray)):
        raise ValueError(f"a key is bytes or hexadecimal text, got {type(key).__name__}")
    if not KEY_SIZES[0] <= len(key) <= KEY_SIZES[1]:
        raise ValueError(f"a key is {KEY_SIZES[0]} to {KEY_SIZES[1]} bytes "
                         f"({2 * KEY_SIZES[0]} to {2 * KEY_SIZES[1]} hex digits), "
                         f"got {len(key)}")
    return bytes(key)


def new_key() -> bytes:
    """:data:`KEY_SIZE` random bytes."""
    return secrets.token_bytes(KEY_SIZE)


def read_key_file(path: str | os.PathLike) -> bytes:
    """The key in the file ``path`` (hex digits; white space around them is ignored);
    ``ValueError`` naming the file for one that is missing, not a regular file, too long
    or not a key."""
    try:
        with open(path, "rb") as file:
            if not stat.S_ISREG(os.fstat(file.fileno()).st_mode):
                raise ValueError(f"key file {os.fspath(path)!r} is not a regular file")
            text = file.read(MAX_KEY_FILE + 1)
    except OSError as error:
        raise ValueError(f"key file {os.fspath(path)!r}: {error.strerror or error}") from None
    if len(text) > MAX_KEY_FILE:
        raise ValueError(f"key file {os.fspath(path)!r} is longer than {MAX_KEY_FILE} bytes")
    try:
        return as_key(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError) as error:
        reason = "not ASCII text" if isinstance(error, UnicodeDecodeError) else error
        raise ValueError(f"key file {os.fspath(path)!r}: {reason}") from None


def tag(key: bytes, body: bytes) -> bytes:
    """The tag that authenticates ``body``: HMAC-SHA256 with ``key``, its first
    :data:`TAG_SIZE` bytes."""
    return hmac.digest(key, body, "sha256")[:TAG_SIZE]


def _authenticated(datagram: bytes, key: bytes) -> bool:
    body, received = datagram[:-TAG_SIZE], datagram[-TAG_SIZE:]
    return hmac.compare_digest(tag(key, body), received)


def new_stream() -> int:
    """A random non-zero stream number (a master draws one when it starts)."""
    return secrets.randbits(64) or 1


def new_launch() -> int:
    """A random non-zero launch number (a receiver draws one when it starts)."""
    return secrets.randbits(64) or 1


@dataclass(frozen=True)
class Command:
    """One decoded command (:func:`decode_command`)."""

    kind: str  # "pose" or "twist"
    ee: int
    buttons: int
    sequence: int
    device_time: float
    values: tuple[float, ...]  # 7 numbers: a pose's x y z qw qx qy qz, a twist's v w and 0
    stream: int = 0
    launch: int = 0  # the receiver's launch the master means (0: a hello)


def encode_command(kind: str, values, sequence: int, device_time: float, ee: int = 0,
                   buttons: int = 0, *, key: bytes, stream: int = 1, launch: int = 0) -> bytes:
    """A command datagram (what a master sends) for the receiver's ``launch`` (0: a hello,
    before the master has heard it), tagged with ``key``; a twist takes 6 values."""
    codes = {name: code for code, name in KINDS.items()}
    if kind not in codes:
        raise ValueError(f"a command's kind is 'pose' or 'twist', got {kind!r}")
    values = [float(v) for v in values]
    if kind == "twist" and len(values) == 6:
        values.append(0.0)
    if len(values) != 7:
        raise ValueError(f"a {kind} command takes {7 if kind == 'pose' else 6} values, "
                         f"got {len(values)}")
    body = COMMAND_FORMAT.pack(MAGIC_COMMAND, VERSION, codes[kind], ee, buttons,
                               sequence & 0xFFFFFFFF, float(device_time), *values,
                               stream & 0xFFFFFFFFFFFFFFFF, launch & 0xFFFFFFFFFFFFFFFF)
    return body + tag(key, body)


def decode_command(datagram: bytes, ee: int, key: bytes) -> Command:
    """The command in ``datagram`` for EE ``ee`` (the one its source drives), or
    :class:`PacketError` naming why not (reasons: ``version``, ``malformed``,
    ``unauthenticated``, ``wrong_ee``, ``not_finite``, ``out_of_range``). The tag is
    checked before any field past the version is read."""
    if datagram[:4] == MAGIC_COMMAND and len(datagram) > 4 and datagram[4] != VERSION:
        raise PacketError("version", f"a protocol version {datagram[4]} master: this is "
                                     f"version {VERSION} (update the master)")
    if len(datagram) != COMMAND_SIZE:
        raise PacketError("malformed", f"{len(datagram)} bytes, a command has {COMMAND_SIZE}")
    if datagram[:4] != MAGIC_COMMAND:
        raise PacketError("malformed", f"magic {datagram[:4]!r}, expected {MAGIC_COMMAND!r}")
    if not _authenticated(datagram, key):
        raise PacketError("unauthenticated", "its tag is not this key's")
    _, _, kind, packet_ee, buttons, sequence, device_time, *values, stream, launch = \
        COMMAND_FORMAT.unpack(datagram[:-TAG_SIZE])
    if kind not in KINDS or buttons & ~BUTTON_MASK:
        raise PacketError("malformed", f"kind {kind}, buttons {buttons:#x}")
    if packet_ee != ee:
        raise PacketError("wrong_ee", f"for EE {packet_ee}, this source drives EE {ee}")
    if not (math.isfinite(device_time) and all(math.isfinite(v) for v in values)):
        raise PacketError("not_finite", "a number is not finite")
    if kind == KIND_POSE:
        norm = math.sqrt(sum(v * v for v in values[3:]))
        if (math.hypot(*values[:3]) > MAX_DEVICE_POSITION
                or not QUATERNION_NORM[0] <= norm <= QUATERNION_NORM[1]):
            raise PacketError("out_of_range", "position farther than "
                              f"{MAX_DEVICE_POSITION:g} m or quaternion norm {norm:.3g}")
        values[3:] = [v / norm for v in values[3:]]
    elif (math.hypot(*values[:3]) > MAX_DEVICE_SPEED[0]
          or math.hypot(*values[3:6]) > MAX_DEVICE_SPEED[1] or values[6] != 0.0):
        raise PacketError("out_of_range", "twist faster than "
                          f"{MAX_DEVICE_SPEED[0]:g} m/s or {MAX_DEVICE_SPEED[1]:g} rad/s")
    return Command(KINDS[kind], ee, buttons, sequence, device_time, tuple(values), stream,
                   launch)


@dataclass(frozen=True)
class Feedback:
    """One feedback datagram's content (:func:`encode_feedback`, :func:`decode_feedback`)."""

    state: FeedbackState
    ee: int
    sequence: int
    applied: int
    device_time: float
    wrench: tuple[float, ...]  # force (N), torque (N m), device frame
    latency: float  # s
    port_force_measured: bool = False
    launch: int = 0  # the receiver's launch


def encode_feedback(feedback: Feedback, key: bytes) -> bytes:
    body = FEEDBACK_FORMAT.pack(MAGIC_FEEDBACK, VERSION, int(feedback.state), feedback.ee,
                                PORT_FORCE_MEASURED if feedback.port_force_measured else 0,
                                feedback.sequence & 0xFFFFFFFF, feedback.applied & 0xFFFFFFFF,
                                feedback.device_time, *feedback.wrench, feedback.latency,
                                feedback.launch & 0xFFFFFFFFFFFFFFFF)
    return body + tag(key, body)


def decode_feedback(datagram: bytes, key: bytes) -> Feedback:
    """What a master reads; :class:`PacketError` for a datagram that is not a feedback
    tagged with ``key``."""
    if len(datagram) != FEEDBACK_SIZE:
        raise PacketError("malformed", f"{len(datagram)} bytes, a feedback has {FEEDBACK_SIZE}")
    if datagram[:4] != MAGIC_FEEDBACK or datagram[4] != VERSION:
        raise PacketError("malformed", f"not a version-{VERSION} feedback")
    if not _authenticated(datagram, key):
        raise PacketError("unauthenticated", "its tag is not this key's")
    _, _, state, ee, flags, sequence, applied, device_time, *rest = \
        FEEDBACK_FORMAT.unpack(datagram[:-TAG_SIZE])
    if state not in FeedbackState._value2member_map_:
        raise PacketError("malformed", f"state {state}")
    return Feedback(FeedbackState(state), ee, sequence, applied, device_time, tuple(rest[:6]),
                    rest[6], bool(flags & PORT_FORCE_MEASURED), rest[7])
