"""What moves a target: an input source (docs/design.md section 19.1).

A source gives, at its own rate, timestamped samples of a pose (a master's stylus, the
browser's gizmo) or of a twist (rate control: a SpaceMouse), with its buttons. Another
thread (a socket's, a device's) :meth:`InputSource.offer` s them; the control tick
:meth:`InputSource.take` s the newest once per period, so a sample that a newer one
replaced before any tick used it is counted, never silently lost. The tick reports back
when a command used a sample (:meth:`InputSource.used`: its arrival-to-command latency)
and what the operator should feel (:meth:`InputSource.set_feedback`).
"""

from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass

import numpy as np

from .protocol import CLUTCH, FeedbackState

#: latencies kept per source (65 s at 1 kHz)
LATENCY_WINDOW = 1 << 16
#: the reasons a sample is dropped, in the order the status lists them
DROP_REASONS = ("malformed", "version", "unauthenticated", "other_launch", "wrong_ee",
                "not_finite", "out_of_range", "out_of_order", "replayed", "stale", "foreign")


@dataclass(frozen=True)
class InputSample:
    """One reading of a source, in the device's frame (x right, y up, z towards the
    operator; docs/design.md section 19.1).

    kind : ``"pose"`` (values: x y z in m, quaternion w x y z, unit) or ``"twist"``
        (values: v x y z in m/s, w x y z in rad/s).
    buttons : bit 0 (:data:`~teleop.inputs.protocol.CLUTCH`) the device's clutch is held,
        bit 1 the mode button.
    sequence : the device's count of its samples.
    arrival : when it arrived (``time.perf_counter()``, s).
    """

    kind: str
    values: tuple[float, ...]
    buttons: int
    sequence: int
    arrival: float

    @property
    def clutched(self) -> bool:
        return bool(self.buttons & CLUTCH)


class LatencyWindow:
    """The last :data:`LATENCY_WINDOW` arrival-to-command latencies (s) of a source,
    written by the control thread only."""

    def __init__(self, size: int = LATENCY_WINDOW) -> None:
        self._values = np.zeros(size)
        self.count = 0

    def add(self, latency: float) -> None:
        self._values[self.count % self._values.size] = latency
        self.count += 1

    def values(self) -> np.ndarray:
        """The kept latencies (s), oldest first."""
        n = min(self.count, self._values.size)
        start = self.count % self._values.size if self.count > self._values.size else 0
        return np.roll(self._values[:n], -start)


class InputSource:
    """The base of every input source: the newest sample waiting for the control tick,
    the counts, the latencies, the feedback to render.

    name : what the operator reads (``udp:9870``, ``spacemouse``).
    ee : the index of the end effector it drives.
    watchdog : whether a silence longer than the app's timeout releases it (a network
        master streams even at rest; a SpaceMouse is silent at rest).
    """

    watchdog = True
    #: whether it renders feedback (the app computes a wrench only for those that do)
    renders_feedback = False

    def __init__(self, name: str, ee: int = 0) -> None:
        self.name = name
        self.ee = ee
        self._lock = threading.Lock()
        self._pending: InputSample | None = None
        #: when the newest valid sample arrived (``perf_counter``), None before any
        self.last_arrival: float | None = None
        self.counts: Counter[str] = Counter()
        self.latencies = LatencyWindow()
        self.applied_sequence = 0
        self.last_latency = float("nan")
        #: what went wrong with the device, for the operator ("" while nothing has)
        self.problem = ""

    def start(self) -> None:
        """Begin receiving (a thread of the source's own); the base has none."""

    def close(self) -> None:
        """Stop receiving and free the device or socket."""

    def offer(self, sample: InputSample) -> None:
        """A new valid sample (from the source's thread); one not yet taken is replaced
        and counted ``superseded``."""
        with self._lock:
            if self._pending is not None:
                self.counts["superseded"] += 1
            self._pending = sample
            self.last_arrival = sample.arrival
            self.counts["accepted"] += 1

    def take(self) -> InputSample | None:
        """The newest sample not yet taken, or None (the control tick)."""
        with self._lock:
            sample, self._pending = self._pending, None
            return sample

    def used(self, sample: InputSample, command_time: float) -> None:
        """A robot command computed at ``command_time`` (``perf_counter``) used ``sample``."""
        self.last_latency = command_time - sample.arrival
        self.latencies.add(self.last_latency)
        self.applied_sequence = sample.sequence
        self.count("applied")

    def count(self, what: str, number: int = 1) -> None:
        """Add ``number`` to the count ``what`` (from any thread)."""
        with self._lock:
            self.counts[what] += number

    def counts_now(self) -> dict[str, int]:
        """A consistent copy of the counts."""
        with self._lock:
            return dict(self.counts)

    def set_feedback(self, wrench: np.ndarray, state: FeedbackState,
                     port_force_measured: bool) -> None:
        """The wrench (force N, torque N m, in the device's frame) the operator should
        feel now; a source that renders none ignores it."""

    def dropped(self) -> int:
        """Datagrams or reports refused, every reason together."""
        counts = self.counts_now()
        return sum(counts.get(reason, 0) for reason in DROP_REASONS)

    def statistics(self, window: int | None = None) -> dict:
        """The counts, the drops by reason (``drop_reasons`` names them) and the
        latency's p50 / p99 (ms) over the last ``window`` commands (None: all kept)."""
        counts = self.counts_now()
        latencies = self.latencies.values()[-(window or LATENCY_WINDOW):]
        p50, p99 = (np.percentile(latencies, (50, 99)) if latencies.size
                    else (float("nan"), float("nan")))
        return {"source": self.name, "ee": self.ee, "received": 0, **counts,
                "dropped": self.dropped(), "drop_reasons": DROP_REASONS,
                "latency_p50_ms": 1e3 * float(p50), "latency_p99_ms": 1e3 * float(p99)}
