"""The control tick: one control period of every robot, called by the control thread
(docs/design.md section 5.3). Every tick computes what the controllers need; the measures
of the live plots and the status are taken on the history ticks only. The collision rows
the view draws are those the controllers computed for their own step (no second
computation on the control thread). :class:`Ticker` is the component ``app.ticker`` of
:class:`web.app.TeleopApp`."""

from __future__ import annotations

import math
import threading

import numpy as np
import pinocchio as pin

from constraints.collision import CollisionRows
from teleop.loop import TeleopLoop
from teleop.loop import PendingStep
from teleop.loop.moving_geometry import advance, steer

from .robots import Robots
from .collisions import CollisionScene
from .console import Console
from .devices import InputDevices
from .editing import ConstraintEditing
from .force_control import ForceControl
from .limits import HISTORY_RATE
from .homing import WayHome
from .placed import PlacedEntry
from .recording import SessionRecording

#: moved geometry is written to a recording every this many ticks while it moves
RECORD_MOVES_EVERY = 10


class Ticker:
    """The control tick of :class:`web.app.TeleopApp` (``app.ticker``): its state is how
    many ticks ran (:attr:`ticks`), the loops' hot path in the last one
    (:attr:`advance_us`) and when the next history sample is due; it reads and advances
    the components given at construction, under the session's lock."""

    def __init__(self, lock: threading.RLock, robots: Robots, console: Console,
                 constraints: ConstraintEditing, collisions: CollisionScene,
                 devices: InputDevices, homing: WayHome, recorder: SessionRecording,
                 force: ForceControl) -> None:
        self._lock = lock
        self._robots = robots
        self._console = console
        self._constraints = constraints
        self._collisions = collisions
        self._devices = devices
        self._homing = homing
        self._recorder = recorder
        self._force = force
        self.ticks = 0
        #: the loops' hot path in the last tick (us): every robot's ``TeleopLoop.advance``,
        #: the controllers' steps included (the control thread's status splits the tick by it)
        self.advance_us = 0.0
        self._next_history = 0.0

    def restart_history(self, t: float) -> None:
        """The next history sample is due at time ``t`` (s): a scene just applied starts
        its history there (:mod:`.scenes`)."""
        with self._lock:
            self._next_history = t

    def step(self) -> float:
        """One control period for every robot (called by the control thread), the input
        devices' samples applied before it (:mod:`.devices`); returns the
        time the controllers took (us), and leaves the loops' whole hot path in
        :attr:`advance_us`.

        Every tick computes what the controllers need; the measures of the live plots and
        the status (constraint errors, EE error, ...) are taken on the history ticks only
        (:data:`HISTORY_RATE`).
        """
        with self._lock:
            dt = self._robots.config.dt
            moving = [entry for entry in (*self._constraints.entries.values(),
                                          *self._collisions.obstacles.values())
                      if not entry.settled]
            if moving:
                self._steer(moving, dt)
            if self._devices:
                self._devices.apply(dt, self._console.inputs, self._robots.loops, self._console.clutch,
                                   self._console.motion_scale)
            if self._homing.active:
                self._follow_homing()
            targets, start = [hand.target for hand in self._console.inputs], self._robots.now
            self._force.feed(self._robots.loops)  # each force law's sensor reading
            held: dict[str, CollisionRows] = {}
            pending = {which: self._advance(which, loop, targets, held)
                       for which, loop in self._robots.loops.items()}
            for which, loop in self._robots.loops.items():  # every period's port force, for its peak
                measures = None if loop.plant is None else loop.plant.measures()
                forces = getattr(measures, "port_forces", None)  # a plant's own measures
                if forces is not None:
                    self._robots.traces[which].feel_port_forces(forces)
            self._collisions.keep(held)
            history = start >= self._next_history - 0.5 * dt
            if self._devices:
                self._devices.commanded(history, self.ticks, self._console.inputs, self._robots.loops["main"],
                                       self._collisions.rows.get("main"),
                                       self._collisions.avoidance.detection_distance)
            if history:
                self._measure(pending, moving, dt, held)
                self._next_history = start + 1.0 / HISTORY_RATE
            else:
                for entry in moving:  # where the period took the geometry
                    advance(entry.moved, dt)
            self.ticks += 1
            self.advance_us = sum(step.tick_time_us for step in pending.values())
            return sum(step.step_time_us for step in pending.values())

    def _follow_homing(self) -> None:
        """The targets on the way home at the app's time (caller holds the lock, once a
        period before the loops advance, while :attr:`_homing` is active; the gizmos stay,
        whose next motion moves the targets from there); once the run is over, the
        targets stay there and the session's task mode returns (:mod:`.homing`)."""
        poses, over = self._homing.targets(self._robots.now, self._robots.loops["main"].q)
        for ee, pose in enumerate(poses):
            self._console.inputs[ee].target = pose
            self._recorder.target(ee, pose)
        if over:
            self._homing.end()
            self._robots.apply_task_modes()

    def _advance(self, which: str, loop: TeleopLoop, targets: list[pin.SE3],
                 held: dict[str, CollisionRows]) -> PendingStep:
        """Robot ``which``'s hot path (:meth:`TeleopLoop.advance`); the collision rows its
        controller computed for this step (the avoidance's :attr:`last_rows`, at the
        configuration the command was computed from) go into ``held``: the view reads
        them (:attr:`collision_rows`, immutable) instead of the control thread computing
        them again."""
        before = self._collisions.avoidance.last_rows
        step = loop.advance(targets)
        rows = self._collisions.avoidance.last_rows
        if rows is not before and rows is not None:
            held[which] = rows
        return step

    def _steer(self, moving: list[PlacedEntry], dt: float) -> None:
        """Moved geometry (a constraint's, an obstacle) glides towards its goal, with
        feed-forward; settles there. A recording gets the constraints' moves."""
        alpha = 1.0 - math.exp(-dt / self._robots.config.target_time_constant)
        for entry in moving:
            geometry = entry.moved
            if float(np.linalg.norm(entry.goal - geometry.position)) < 1e-12:
                geometry.move_to(entry.goal, (0.0, 0.0, 0.0))
                entry.settled = True
                continue
            steer(geometry, entry.goal, dt, smoothing=alpha)
            if (self._recorder.active and entry.recorded
                    and self.ticks % RECORD_MOVES_EVERY == 0 and np.any(geometry.velocity)):
                self._recorder.move(entry.id,
                                   geometry.position, geometry.velocity)

    def _measure(self, pending: dict[str, PendingStep],
                 moving: list[PlacedEntry], dt: float,
                 held: dict[str, CollisionRows]) -> None:
        """The measures of the tick just advanced (``pending``), appended to the history:
        the command's, then, once the geometry has moved on, the end of the period's. The
        collision rows of a robot whose controller computed none this tick (not in
        ``held``) are measured here, where its command was computed from
        (:meth:`.collisions.CollisionScene.measure`)."""
        for which, loop in self._robots.loops.items():  # before the geometry moves on
            loop.measure_command(pending[which])
        self._collisions.measure({which: step.sensed for which, step in pending.items()
                                  if which not in held})
        for entry in moving:
            advance(entry.moved, dt)
        main_qd = self._robots.loops["main"].last_qd
        for which, loop in self._robots.loops.items():
            record = loop.measure(pending[which])
            self._robots.last_records[which] = record
            deviation = 0.0 if which == "main" else float(np.linalg.norm(loop.last_qd - main_qd))
            self._robots.traces[which].add(record, deviation, self._collisions.traced_distance(which))
        self._force.measure(self._robots.loops["main"])
