"""The browser session's core, without any browser: state, actions, the control thread.

Everything the UI does goes through :class:`TeleopApp`, so it can be tested without
viser. All public methods are thread-safe (one lock); actions that cannot be done raise
``ValueError`` with a message meant for the operator (the UI shows it as a notification).

Threading (docs/design.md section 5): :class:`ControlThread` calls :meth:`TeleopApp.step` at
the control rate and never touches viser; the view thread reads :meth:`TeleopApp.snapshot`.
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import math
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np
import pinocchio as pin

from constraints import Barrier, Constraint, Hole, Plane, PointLock
from constraints.kinematics import frame_placement
from constraints.validation import as_number, as_vector
from teleop.controller_specs import make_controller
from teleop.experiments.sessions import SessionRecorder
from teleop.loop import LoopConfig, StepRecord, TeleopLoop
from teleop.loop.moving_geometry import advance, steer
from teleop.robots import Robot

#: the operator's target and moved geometry are smoothed with this time constant (s)
DEFAULT_SMOOTHING = 0.05
#: EE speed caps of the operator's command. A dragged gizmo jumps by centimetres; at these
#: speeds the sda10f (about 40 rad/s of joint speed per m/s at its EE with a hole on link 6)
#: stays within its joint-velocity limits and the hole's discretisation error below 1 um.
MAX_LINEAR_SPEED = 0.05  # m/s
MAX_ANGULAR_SPEED = 0.5  # rad/s
#: seconds of history kept for the live plots
HISTORY_SECONDS = 10.0
#: history samples per second (every control tick would be 1000/s: far more than a plot needs)
HISTORY_RATE = 50.0


@dataclass
class ConstraintEntry:
    """A constraint placed by the operator, with the geometry its gizmo drives."""

    id: str
    constraint: Constraint
    goal: np.ndarray  # where the operator put it (the control loop moves towards it)

    @property
    def kind(self) -> str:
        """The constraint's ``kind`` ("hole", "plane", "barrier", "point_lock")."""
        return self.constraint.kind

    @property
    def position(self) -> np.ndarray:
        """Where the geometry is now (world reference point, a copy)."""
        return self.constraint.position


@dataclass
class Trace:
    """Rolling history of one robot's measures for the live plots."""

    t: collections.deque = field(default_factory=lambda: collections.deque(maxlen=int(HISTORY_SECONDS * HISTORY_RATE)))
    constraint_error: collections.deque = field(default_factory=lambda: collections.deque(maxlen=int(HISTORY_SECONDS * HISTORY_RATE)))
    constraint_velocity: collections.deque = field(default_factory=lambda: collections.deque(maxlen=int(HISTORY_SECONDS * HISTORY_RATE)))
    ee_error: collections.deque = field(default_factory=lambda: collections.deque(maxlen=int(HISTORY_SECONDS * HISTORY_RATE)))
    step_time: collections.deque = field(default_factory=lambda: collections.deque(maxlen=int(HISTORY_SECONDS * HISTORY_RATE)))

    def add(self, record: StepRecord) -> None:
        self.t.append(record.t)
        self.constraint_error.append(max(record.constraint_error, record.barrier_penetration))
        self.constraint_velocity.append(float(np.linalg.norm(record.constraint_velocity)))
        self.ee_error.append(record.ee_position_error)
        self.step_time.append(record.step_time_us)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.array(getattr(self, name), dtype=float)
                for name in ("t", "constraint_error", "constraint_velocity", "ee_error", "step_time")}


class TeleopApp:
    """One robot (plus an optional ghost) teleoperated from one shared target.

    Parameters
    ----------
    robot : the robot.
    controller : controller spec of the main robot (``cjm``, ``qp:daqp``, ``mink:daqp``...).
    ghost : spec of a second, translucent robot driven from the same target, or None.
    rate : control rate (Hz).
    record_dir : where session recordings go.
    """

    def __init__(self, robot: Robot, controller: str = "cjm", ghost: str | None = None,
                 rate: float = 1000.0, kp: float = 20.0, record_dir: str | Path = "sessions") -> None:
        self.robot = robot
        self._lock = threading.RLock()
        self._view_data = robot.model.createData()  # for geometry queries, under the lock
        self.config = LoopConfig(rate=rate, kp=kp, target_time_constant=DEFAULT_SMOOTHING,
                                 max_linear_speed=MAX_LINEAR_SPEED,
                                 max_angular_speed=MAX_ANGULAR_SPEED)
        self.gain = 100.0
        self.damping = 0.0
        self.record_dir = Path(record_dir)
        self.entries: dict[str, ConstraintEntry] = {}
        self._ids = itertools.count(1)
        self.specs = {"main": controller}
        self.loops: dict[str, TeleopLoop] = {"main": self._make_loop(controller)}
        self.traces: dict[str, Trace] = {"main": Trace()}
        self.last_records: dict[str, StepRecord | None] = {"main": None}
        if ghost:
            self.set_ghost(ghost)
        self.target = self.loops["main"].ee_placement()
        self.recorder: SessionRecorder | None = None
        self._record_start = 0.0
        self._next_history = 0.0
        self.ticks = 0

    # -- construction helpers ------------------------------------------------------------

    def _make_loop(self, spec: str, q: np.ndarray | None = None) -> TeleopLoop:
        constraints = [e.constraint for e in getattr(self, "entries", {}).values()]
        controller = make_controller(spec, self.robot, constraints, dt=self.config.dt)
        self._apply_damping(controller)
        return TeleopLoop(self.robot, controller, q0=q, config=self.config)

    def _apply_damping(self, controller) -> None:
        if hasattr(controller, "policy"):  # the CJM's damped least squares
            from controllers.linalg import DampingPolicy

            old = controller.policy
            controller.policy = DampingPolicy(self.damping, old.threshold, old.max_damping)

    def _sync_constraints(self) -> None:
        constraints = [e.constraint for e in self.entries.values()]
        for loop in self.loops.values():
            loop.set_constraints(constraints)

    @property
    def now(self) -> float:
        return self.loops["main"].t

    # -- operator actions ------------------------------------------------------------------

    def set_target(self, position, wxyz) -> None:
        """The operator's target pose (world position, quaternion w, x, y, z)."""
        position = as_vector(position, 3, "target position")
        wxyz = as_vector(wxyz, 4, "target quaternion")
        if np.linalg.norm(wxyz) < 1e-9:
            raise ValueError("the target quaternion must be non-zero")
        rotation = pin.Quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized().matrix()
        with self._lock:
            self.target = pin.SE3(rotation, position)
            if self.recorder is not None:
                self.recorder.target(self.now - self._record_start, self.target)

    def _link_placement(self, link: str) -> pin.SE3:
        """World placement of ``link`` on the main robot now (caller holds the lock)."""
        return frame_placement(self.robot.model, self.loops["main"].q, link, self._view_data)

    def add_constraint(self, constraint: Constraint) -> str:
        """Place a constraint of any kind where it is; it takes the app's drift gain.

        Returns its id (``"<kind>-<n>"``). A constraint the controllers refuse (unknown
        link, gain unstable at this rate) raises ``ValueError`` and is not placed.
        """
        if not isinstance(constraint, Constraint):
            raise ValueError(f"expected a constraint, got {constraint!r}")
        with self._lock:
            constraint.gain = self.gain
            entry_id = f"{constraint.kind}-{next(self._ids)}"
            self.entries[entry_id] = ConstraintEntry(entry_id, constraint, constraint.position)
            try:
                self._sync_constraints()
            except ValueError:
                del self.entries[entry_id]
                self._sync_constraints()
                raise
            if self.recorder is not None:
                self.recorder.add(self.now - self._record_start, entry_id, constraint)
            return entry_id

    def _link_distance(self, distance: float, what: str) -> float:
        """``distance`` (m along the constrained link's axis) if it lies on the arm: between
        the link's joint (0) and the EE's distance from it; else ``ValueError``."""
        distance = as_number(distance, what)
        with self._lock:
            link = self._link_placement(self.robot.constrained_link)
            reach = float(np.linalg.norm(link.actInv(
                self._link_placement(self.robot.ee_frame).translation)))
        if not 0.0 <= distance <= reach:
            raise ValueError(f"{what} must be between 0 and {reach:.3f} m (from the joint of "
                             f"{self.robot.constrained_link} to the tool tip), got {distance:g} m")
        return distance

    def add_hole(self, distance: float) -> str:
        """A hole on the constrained link, ``distance`` m along its axis, where it is now."""
        distance = self._link_distance(distance, "hole distance")
        with self._lock:
            return self.add_constraint(Hole.on_link(self.robot, self.loops["main"].q, distance=distance))

    def add_point_lock(self, distance: float) -> str:
        """Lock the constrained link's point ``distance`` m along its axis where it is now."""
        distance = self._link_distance(distance, "point lock distance")
        with self._lock:
            return self.add_constraint(
                PointLock.on_link(self.robot, self.loops["main"].q, distance=distance))

    def add_plane(self, distance: float, normal, barrier: bool = False, offset: float = 0.0) -> str:
        """A plane (or barrier) through the link point ``distance`` m along the link axis.

        ``normal`` is a world direction (normalised here; zero is refused). A barrier may
        sit ``offset`` m below the point along the normal (the point must be on its
        positive side).
        """
        distance = self._link_distance(distance, "plane distance")
        offset = as_number(offset, "barrier offset")
        normal = as_vector(normal, 3, "plane normal")
        if np.linalg.norm(normal) < 1e-9:
            raise ValueError("the plane normal must be a non-zero 3-vector")
        normal = normal / np.linalg.norm(normal)
        with self._lock:
            q = self.loops["main"].q
            point = self._link_placement(self.robot.constrained_link).act(
                distance * np.asarray(self.robot.link_axis))
            cls = Barrier if barrier else Plane
            constraint = cls.through_link_point(
                self.robot, q, normal=normal, distance=distance,
                plane_point=point - offset * normal)
            return self.add_constraint(constraint)

    def move_constraint(self, entry_id: str, position) -> None:
        """Move a constraint's geometry (hole centre, plane point, lock target): the robot
        follows it."""
        position = as_vector(position, 3, "constraint position")
        with self._lock:
            if entry_id not in self.entries:
                raise ValueError(f"no constraint {entry_id!r}")
            self.entries[entry_id].goal = position.copy()

    def remove_constraint(self, entry_id: str) -> None:
        with self._lock:
            if self.entries.pop(entry_id, None) is None:
                raise ValueError(f"no constraint {entry_id!r}")
            self._sync_constraints()
            if self.recorder is not None:
                self.recorder.remove(self.now - self._record_start, entry_id)

    def set_controller(self, spec: str) -> None:
        """Switch the main robot's controller, keeping its state."""
        with self._lock:
            self._switch("main", spec)

    def set_ghost(self, spec: str | None) -> None:
        """Show a translucent second robot driven by ``spec`` (None removes it)."""
        with self._lock:
            if not spec:
                for store in (self.loops, self.specs, self.traces, self.last_records):
                    store.pop("ghost", None)
                return
            if "ghost" in self.loops:
                self._switch("ghost", spec)
                return
            self.loops["ghost"] = self._make_loop(spec, q=self.loops["main"].q.copy())
            self.specs["ghost"] = spec
            self.traces["ghost"] = Trace()
            self.last_records["ghost"] = None

    def _switch(self, which: str, spec: str) -> None:
        self.loops[which] = self._rebuilt(which, spec)  # raises ValueError on a bad spec
        self.specs[which] = spec

    def _rebuilt(self, which: str, spec: str) -> TeleopLoop:
        """A new loop for robot ``which`` with ``spec`` and the current config, same state."""
        old = self.loops[which]
        loop = self._make_loop(spec, q=old.q.copy())
        loop.t = old.t
        return loop

    def set_gain(self, gain: float) -> None:
        """Gain K (1/s) of every constraint: the drift feedback of the equalities, the
        approach rate of the barriers. A gain some placed constraint cannot take at this
        rate (``K dt`` too large) raises ``ValueError`` and changes nothing."""
        gain = as_number(gain, "gain")
        if not 0.0 <= gain * self.config.dt < 2.0:
            raise ValueError(f"gain must be in [0, {2.0 / self.config.dt:g}) 1/s at this rate")
        with self._lock:
            previous, self.gain = self.gain, gain
            for entry in self.entries.values():
                entry.constraint.gain = gain
            try:
                self._sync_constraints()  # the controllers check the gains and refresh
            except ValueError:
                self.gain = previous
                for entry in self.entries.values():
                    entry.constraint.gain = previous
                self._sync_constraints()
                raise

    def set_damping(self, damping: float) -> None:
        """Constant DLS damping lambda of the CJM (paper eq 35)."""
        damping = as_number(damping, "damping", 0.0)
        with self._lock:
            self.damping = damping
            for loop in self.loops.values():
                self._apply_damping(loop.controller)

    def set_rate(self, rate: float) -> None:
        """Control rate (Hz); rebuilds the loops (QP limits depend on dt), keeps the state."""
        rate = as_number(rate, "the control rate")
        if not 50.0 <= rate <= 5000.0:
            raise ValueError("the control rate must be between 50 and 5000 Hz")
        with self._lock:
            previous = self.config
            self.config = dataclasses.replace(self.config, rate=rate)
            try:  # every loop rebuilt at the new dt (gains checked), or none
                loops = {which: self._rebuilt(which, self.specs[which]) for which in self.loops}
            except ValueError:
                self.config = previous
                raise
            self.loops.update(loops)

    def home(self) -> None:
        """Robots back home, target on the home EE pose, constraints removed."""
        with self._lock:
            for entry_id in list(self.entries):
                self.remove_constraint(entry_id)
            for loop in self.loops.values():
                t = loop.t
                loop.reset()
                loop.t = t
            self.target = self.loops["main"].ee_placement()
            if self.recorder is not None:
                self.recorder.target(self.now - self._record_start, self.target)

    # -- recording ---------------------------------------------------------------------

    def start_recording(self, path: str | Path | None = None) -> Path:
        with self._lock:
            if self.recorder is not None:
                raise ValueError(f"already recording to {self.recorder.path}")
            if path is None:
                path = self.record_dir / f"session-{datetime.now():%Y%m%d-%H%M%S}.jsonl"
            self.recorder = SessionRecorder(path, self.robot, self.loops["main"].q,
                                            rate_hz=self.config.rate, kp=self.config.kp,
                                            target_time_constant_s=self.config.target_time_constant)
            self._record_start = self.now
            for entry in self.entries.values():
                self.recorder.add(0.0, entry.id, entry.constraint)
            self.recorder.target(0.0, self.target)
            return self.recorder.path

    def stop_recording(self) -> Path:
        with self._lock:
            if self.recorder is None:
                raise ValueError("not recording")
            recorder, self.recorder = self.recorder, None
            recorder.close(self.now - self._record_start)
            return recorder.path

    # -- the control tick ------------------------------------------------------------------

    def step(self) -> None:
        """One control period for every robot (called by the control thread)."""
        with self._lock:
            dt = self.config.dt
            alpha = 1.0 - math.exp(-dt / self.config.target_time_constant)
            for entry in self.entries.values():  # moved geometry glides, with feed-forward
                steer(entry.constraint, entry.goal, dt, smoothing=alpha)
                if (self.recorder is not None and self.ticks % 10 == 0
                        and np.any(entry.constraint.velocity)):
                    self.recorder.move(self.now - self._record_start, entry.id,
                                       entry.constraint.position, entry.constraint.velocity)
            pending = {which: loop.advance(self.target) for which, loop in self.loops.items()}
            for entry in self.entries.values():  # where the period took the geometry
                advance(entry.constraint, dt)
            for which, loop in self.loops.items():
                record = loop.measure(pending[which])
                self.last_records[which] = record
                if record.t >= self._next_history:
                    self.traces[which].add(record)
            if self.now >= self._next_history:
                self._next_history = self.now + 1.0 / HISTORY_RATE
            self.ticks += 1

    # -- what the view draws -----------------------------------------------------------

    def snapshot(self) -> dict:
        """A consistent copy of everything the view shows."""
        with self._lock:
            robots = {}
            for which, loop in self.loops.items():
                record = self.last_records.get(which)
                robots[which] = {
                    "spec": self.specs[which], "q": loop.q.copy(), "t": loop.t,
                    "record": record, "trace": self.traces[which].arrays(),
                    "info": loop.controller.info,
                }
            entries = [{"id": entry.id, "kind": entry.kind, "goal": entry.goal.copy(),
                        "geometry": entry.constraint.geometry(
                            self._link_placement(entry.constraint.link))}
                       for entry in self.entries.values()]
            return {"robots": robots, "constraints": entries,
                    "target": self.target.copy(), "recording": self.recorder is not None,
                    "config": self.config, "gain": self.gain, "damping": self.damping}


class ControlThread:
    """Runs :meth:`TeleopApp.step` at the app's control rate on its own thread.

    Tracks the achieved rate and deadline misses (a tick that started later than one
    period after it was due). Sleeps between ticks; when it falls behind it does not try
    to catch up by bursting (the robot would see a jump), it resynchronises.
    """

    def __init__(self, app: TeleopApp) -> None:
        self.app = app
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="control", daemon=True)
        self.deadline_misses = 0
        self.achieved_rate = 0.0
        self.error: str | None = None

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        clock = time.perf_counter
        next_tick = clock()
        window_start, window_ticks = clock(), 0
        while not self._stop.is_set():
            period = self.app.config.dt
            try:
                self.app.step()
            except Exception as error:  # keep the robot still and say why
                self.error = f"{type(error).__name__}: {error}"
                time.sleep(0.01)
            window_ticks += 1
            now = clock()
            if now - window_start >= 1.0:
                self.achieved_rate = window_ticks / (now - window_start)
                window_start, window_ticks = now, 0
            next_tick += period
            delay = next_tick - clock()
            if delay > 0:
                time.sleep(delay)
            elif delay < -period:
                self.deadline_misses += 1
                next_tick = clock()
