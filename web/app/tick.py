"""The control tick: one control period of every robot, called by the control thread
(docs/design.md section 5.3). Every tick computes what the controllers need; the measures
of the live plots and the status are taken on the history ticks only."""

from __future__ import annotations

import math
import threading

import numpy as np
import pinocchio as pin

from teleop.experiments.sessions import SessionRecorder
from teleop.loop import LoopConfig, StepRecord, TeleopLoop
from teleop.loop.moving_geometry import advance, steer

from .collisions import ObstacleEntry
from .console import EEInput
from .editing import ConstraintEntry
from .limits import HISTORY_RATE
from .trace import Trace

#: moved geometry is written to a recording every this many ticks while it moves
RECORD_MOVES_EVERY = 10


class Tick:
    """The control tick of :class:`web.app.TeleopApp` (its state: ``ticks`` and when the
    next history sample is due)."""

    config: LoopConfig
    loops: dict[str, TeleopLoop]
    traces: dict[str, Trace]
    last_records: dict[str, StepRecord | None]
    entries: dict[str, ConstraintEntry]
    obstacles: dict[str, ObstacleEntry]
    inputs: list[EEInput]
    recorder: SessionRecorder | None
    ticks: int
    _next_history: float
    _lock: threading.RLock

    @property
    def now(self) -> float:
        """The app's time (s): the main robot's loop time."""
        return self.loops["main"].t

    def step(self) -> float:
        """One control period for every robot (called by the control thread); returns the
        time the controllers took (us).

        Every tick computes what the controllers need; the measures of the live plots and
        the status (constraint errors, EE error, ...) are taken on the history ticks only
        (:data:`HISTORY_RATE`).
        """
        with self._lock:
            dt = self.config.dt
            moving = [entry for entry in (*self.entries.values(), *self.obstacles.values())
                      if not entry.settled]
            if moving:
                self._steer(moving, dt)
            targets, start = [hand.target for hand in self.inputs], self.now
            if start >= self._next_history - 0.5 * dt:
                solve_us = self._measured_step(targets, moving, dt)
                self._next_history = start + 1.0 / HISTORY_RATE
            else:
                solve_us = 0.0
                for loop in self.loops.values():  # the hot path only (no measures)
                    solve_us += loop.advance(targets).step_time_us
                for entry in moving:  # where the period took the geometry
                    advance(entry.moved, dt)
            self.ticks += 1
            return solve_us

    def _steer(self, moving: list[ConstraintEntry | ObstacleEntry], dt: float) -> None:
        """Moved geometry (a constraint's, an obstacle) glides towards its goal, with
        feed-forward; settles there. A recording gets the constraints' moves."""
        alpha = 1.0 - math.exp(-dt / self.config.target_time_constant)
        for entry in moving:
            geometry = entry.moved
            if float(np.linalg.norm(entry.goal - geometry.position)) < 1e-12:
                geometry.move_to(entry.goal, (0.0, 0.0, 0.0))
                entry.settled = True
                continue
            steer(geometry, entry.goal, dt, smoothing=alpha)
            if (self.recorder is not None and isinstance(entry, ConstraintEntry)
                    and self.ticks % RECORD_MOVES_EVERY == 0 and np.any(geometry.velocity)):
                self.recorder.move(self.recording_time, entry.id,
                                   geometry.position, geometry.velocity)

    def _measured_step(self, targets: list[pin.SE3],
                       moving: list[ConstraintEntry | ObstacleEntry], dt: float) -> float:
        """A full tick with the measures, appended to the history (the collision rows at
        every robot's configuration among them, :meth:`Collisions._measure_collisions`)."""
        pending = {which: loop.advance(targets) for which, loop in self.loops.items()}
        for which, loop in self.loops.items():  # before the geometry moves on
            loop.measure_command(pending[which])
        for entry in moving:
            advance(entry.moved, dt)
        self._measure_collisions()
        main_qd = self.loops["main"].last_qd
        for which, loop in self.loops.items():
            record = loop.measure(pending[which])
            self.last_records[which] = record
            deviation = 0.0 if which == "main" else float(np.linalg.norm(loop.last_qd - main_qd))
            self.traces[which].add(record, deviation, self.traced_distance(which))
        return sum(step.step_time_us for step in pending.values())
