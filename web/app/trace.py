"""The rolling history of one robot's measures, for the live plots."""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field

import numpy as np

from teleop.loop import StepRecord
from teleop.plants import largest_force

from .limits import HISTORY_RATE, HISTORY_SECONDS

_HISTORY_LENGTH = int(HISTORY_SECONDS * HISTORY_RATE)
#: the plotted measures of each robot, in the order of the plots
TRACE_COLUMNS = ("constraint_error", "constraint_velocity", "ee_error", "step_time",
                 "port_force", "minimum_distance")
#: every column kept: the time, the plotted measures, the ghost's deviation
_NAMES = ("t", *TRACE_COLUMNS, "qd_deviation")


def _deque() -> collections.deque:
    return collections.deque(maxlen=_HISTORY_LENGTH)


@dataclass
class Trace:
    """Rolling history of one robot's measures for the live plots (app time ``t``)."""

    t: collections.deque = field(default_factory=_deque)
    constraint_error: collections.deque = field(default_factory=_deque)
    constraint_velocity: collections.deque = field(default_factory=_deque)
    ee_error: collections.deque = field(default_factory=_deque)
    step_time: collections.deque = field(default_factory=_deque)
    #: the largest port force (N) of a physics plant over the control periods since the
    #: previous sample (its peak, not one period's: a drag's force lasts a few periods);
    #: NaN without one
    port_force: collections.deque = field(default_factory=_deque)
    #: |qd - qd_main| (rad/s): the ghost's deviation from the main robot's command
    qd_deviation: collections.deque = field(default_factory=_deque)
    #: the closest collision pair's distance (m), at most the detection distance; NaN
    #: while collisions are off (:meth:`web.app.collisions.CollisionScene.traced_distance`)
    minimum_distance: collections.deque = field(default_factory=_deque)
    #: the largest port force (N) of the periods since the last sample; NaN: none felt
    _port_peak: float = math.nan

    def feel_port_forces(self, forces: np.ndarray) -> None:
        """One control period's port forces ``(ports, 3)`` (N), kept until the next sample
        if they are the largest since the last."""
        if forces.size:
            largest = largest_force(forces)
            if not largest <= self._port_peak:  # NaN: the first since the last sample
                self._port_peak = largest

    def add(self, record: StepRecord, qd_deviation: float = 0.0,
            minimum_distance: float = math.nan) -> None:
        self.t.append(record.t)
        self.constraint_error.append(max(record.constraint_error, record.barrier_penetration))
        self.constraint_velocity.append(float(np.linalg.norm(record.constraint_velocity)))
        self.ee_error.append(record.ee_position_error)
        self.step_time.append(record.step_time_us)
        if record.plant is None:
            self.port_force.append(math.nan)
        else:  # this sample's period and every one since the last sample
            self.feel_port_forces(record.plant.port_forces)
            self.port_force.append(0.0 if math.isnan(self._port_peak) else self._port_peak)
        self._port_peak = math.nan
        self.qd_deviation.append(qd_deviation)
        self.minimum_distance.append(minimum_distance)

    def columns(self) -> dict[str, list[float]]:
        """A copy of every column (cheap: no array built; :meth:`arrays_of` builds them)."""
        return {name: list(getattr(self, name)) for name in _NAMES}

    def arrays(self) -> dict[str, np.ndarray]:
        return self.arrays_of(self.columns())

    @staticmethod
    def arrays_of(columns: dict[str, list[float]]) -> dict[str, np.ndarray]:
        """:meth:`columns` as arrays, one per column."""
        return {name: np.array(values, dtype=float) for name, values in columns.items()}
