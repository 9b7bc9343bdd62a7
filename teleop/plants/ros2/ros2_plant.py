"""A robot on the other end of ROS 2 as the loop's plant (docs/ros2.md; docs/design.md
section 15.1, the :class:`teleop.loop.Plant` protocol).

:meth:`Ros2Plant.sense` is the last ``sensor_msgs/JointState`` received, joints matched by
name; :meth:`Ros2Plant.actuate` publishes the command (a ``JointGroupVelocityController``'s
``Float64MultiArray`` in the controller's joint order, or CRTK's ``servo_jv``), ends the
period with the robot's next state (not sooner than half a period after the last period's
end, not later than one and a half: the robot's clock paces the loop, since a real robot
does not wait for the controller) and returns the mean velocity that took the loop's
configuration ``q`` to the state then received, ``v = log(q^-1 q_measured) / dt``
(``pin.difference``), so the loop's ``q`` is the robot's.

Safety on the wire: nothing is published before the first state; the robot is stopped
(zeros published, then every period) when the state is older than ``stale_after`` (a
watchdog thread checks it every period: a velocity controller holds its last command
forever), when a state is not finite or lacks a joint, when a command is not finite, on
:meth:`close`, at exit and on any error raised through the plant's ``with`` block; a stop
holds until :meth:`reset` and :attr:`Ros2Measures.stopped` says why. Zeros go out once,
too, when the loop stops actuating for ``stale_after`` (it may command again).

The threads on the wire run real-time (``Ros2Settings.realtime_priority``, SCHED_FIFO 40
by default, below ros2_control's controller manager, :mod:`teleop.plants.ros2.realtime`):
DDS's threads and the watchdog, started real-time, and the thread that calls
:meth:`Ros2Plant.actuate` (the loop's), made real-time at its first call and given its own
scheduling back when it stops actuating for ``stale_after`` (with the idle stop) or the
plant closes, so a command is not late for the robot's update because the machine is busy
(docs/ros2.md "Real-time threads"). A loop that overruns its period never waits for the
robot, so its real-time thread would never sleep: after :data:`OVERRUN_PERIODS` periods
in a row that ended without waiting, the actuating thread is given its own scheduling
back until :meth:`Ros2Plant.reset`. :attr:`Ros2Measures.realtime` says how they run."""

from __future__ import annotations

import atexit
from collections import deque
import math
import threading
import time
from dataclasses import dataclass, field
from typing import ClassVar, Sequence

import numpy as np
import pinocchio as pin
from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState, WaitSet
from cyclonedds.util import duration

from constraints import Constraint

from teleop.heap_freeze import freeze_heap, release_heap
from .joint_map import indices, model_joint_names
from .messages import Float64MultiArray, JointState, OperatingState
from .node import Ros2Node
from .realtime import OVERRUN_PERIODS, hold_realtime, release_realtime, started_realtime
from .settings import Ros2Settings

@dataclass
class Ros2Measures:
    """What the plant knows of the robot over the last period.

    Attributes
    ----------
    stopped : why the plant stopped the robot (zeros published), empty while it commands.
    state_age : the last state's age at the period's end (s); inf before the first.
    states : states received since :meth:`Ros2Plant.reset`.
    command_publishers : writers on the command topic, this plant's included (more than
        one: another node commands the same controller).
    operating_state : CRTK's last ``operating_state.state`` (empty: none or not CRTK).
    idle_stops : zeros published because the loop stopped actuating for ``stale_after``.
    realtime : how the threads on the wire are scheduled (``DDS and watchdog: SCHED_FIFO
        40; actuating: SCHED_FIFO 40``), with the reason when the system refused or the
        actuating thread gave it up for overruns.
    port_forces : (0, 3): the wall's force is not measured over ROS 2.
    port_displacements : (0,).
    """

    stopped: str = ""
    state_age: float = math.inf
    states: int = 0
    command_publishers: int = 0
    operating_state: str = ""
    idle_stops: int = 0
    realtime: str = ""
    port_forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    port_displacements: np.ndarray = field(default_factory=lambda: np.zeros(0))

    #: not a simulated body's measures (no port force, no torque)
    physical: ClassVar[bool] = False

    @property
    def port_force(self) -> float:
        """No port force over ROS 2: 0."""
        return 0.0


class Ros2Plant:
    """A :class:`teleop.loop.Plant` over ROS 2 (module docstring).

    Parameters
    ----------
    robot : the ``teleop.Robot`` (its model's joint names are the robot's on the wire).
    dt : the control period (s).
    settings : :class:`Ros2Settings`.
    """

    def __init__(self, robot, dt: float, settings: Ros2Settings | None = None) -> None:
        if not isinstance(dt, (int, float)) or not math.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        self.model: pin.Model = robot.model
        self.dt = float(dt)
        self.settings = settings or Ros2Settings()
        self.names = model_joint_names(self.model)
        command_joints = self.settings.command_joints or tuple(self.names)
        self._command_order = indices(command_joints, self.names, "the robot model")
        self._command_names = list(command_joints)
        self._lock = threading.Condition(threading.RLock())  # notified at each new state
        self.node, dds_threads = started_realtime(self.settings.realtime_priority,
                                                  lambda: Ros2Node(self.settings.domain))
        crtk = bool(self.settings.crtk)
        self._states = self.node.reader(self.settings.state_topic, JointState)
        command_type = JointState if crtk else Float64MultiArray
        self._writer = self.node.writer(self.settings.commands, command_type)
        self._command_listener = self.node.reader(self.settings.commands, command_type)
        self._operating = (self.node.reader(self.settings.crtk.rstrip("/") + "/operating_state",
                                            OperatingState) if crtk else None)
        self._waitset = WaitSet(self.node.participant)
        self._waitset.attach(ReadCondition(self._states, SampleState.Any | ViewState.Any
                                           | InstanceState.Any))
        self._state_order: np.ndarray | None = None
        #: the last ``settings.command_latency`` commands published, oldest first: the
        #: robot applies them after the state it last sent (:meth:`sense`)
        self._in_flight: deque[np.ndarray] = deque(maxlen=self.settings.command_latency)
        self._state_names: list[str] = []
        self._refused = ""  # why the joint states' names are refused
        self._q: np.ndarray | None = None
        self._received = -math.inf  # time.monotonic() of the last state
        self._commanding = False
        self._actuated = -math.inf  # time.monotonic() of the last command published
        self._fresh = 0  # good states taken since the start
        self._period_start = 0.0  # time.monotonic() when the last period ended
        self._period_fresh = 0  # self._fresh when the last period ended
        self._paced = False  # :meth:`pace` ended the period: the next actuate does not wait
        self._overruns = 0  # periods in a row that ended without waiting
        self._gave_up = False  # real-time given up for overruns, until the next reset
        #: how the threads on the wire run; the actuating thread's added at its first call
        self._scheduling = f"DDS: {dds_threads}; watchdog: "
        #: the id of the thread held real-time while it actuates (:func:`hold_realtime`)
        self._actuating: int | None = None
        self._called = -math.inf  # time.monotonic() of the last call to actuate
        self.last_measures = Ros2Measures()
        self._running = True
        self._closed = False
        self._watchdog = threading.Thread(target=self._watch, name="ros2-watchdog", daemon=True)
        _, watchdog = started_realtime(self.settings.realtime_priority, self._watchdog.start)
        self._scheduling += watchdog
        self.last_measures.realtime = self._scheduling
        atexit.register(self.close)

    # --- the wire -------------------------------------------------------------------
    def _take_states(self) -> None:
        """Every state received since the last call; the newest is kept (caller holds the
        lock). A state without one of the robot's joints, or with a non-finite position,
        stops the robot."""
        for sample in self._states.take(64):
            if not isinstance(sample, JointState):
                continue
            self.last_measures.states += 1
            if list(sample.name) != self._state_names:
                self._state_names = list(sample.name)
                try:
                    self._state_order = indices(self.names, sample.name,
                                                f"{self.settings.state_topic}")
                except ValueError as error:
                    self._state_order = None
                    self._refused = str(error)
                    self._stop(self._refused)
                    continue
            if self._state_order is None:
                continue
            if len(sample.position) != len(sample.name):
                self._stop(f"{self.settings.state_topic}: {len(sample.position)} positions "
                           f"for {len(sample.name)} names")
                continue
            q = np.asarray(sample.position, dtype=float)[self._state_order]
            if not np.all(np.isfinite(q)):
                bad = [self.names[i] for i in np.flatnonzero(~np.isfinite(q))]
                self._stop(f"{self.settings.state_topic}: non-finite position of {bad}")
                continue
            self._q = q
            self._received = time.monotonic()
            self._fresh += 1
            self._lock.notify_all()
        if self._operating is not None:
            for state in self._operating.take(16):
                if isinstance(state, OperatingState):
                    self.last_measures.operating_state = state.state

    def _publish(self, qd: np.ndarray) -> None:
        """``qd`` (model order) on the command topic, and among the commands in flight
        (caller holds the lock)."""
        self._in_flight.append(qd.copy())
        values = [float(v) for v in qd[self._command_order]]
        if self.settings.crtk:
            self._writer.write(JointState(name=self._command_names, velocity=values))
        else:
            self._writer.write(Float64MultiArray(data=values))

    def _stop(self, reason: str) -> None:
        """Zeros published and the reason kept (the first reason stays) (caller holds the
        lock); nothing published before the first command."""
        if not self.last_measures.stopped:
            self.last_measures.stopped = reason
        if self._commanding:
            self._publish(np.zeros(self.model.nv))

    def _check_stale(self, now: float) -> None:
        age = now - self._received
        self.last_measures.state_age = age
        if self._q is not None and age > self.settings.stale_after:
            self._stop(f"joint states stale: none for {age * 1000:.0f} ms "
                       f"(limit {self.settings.stale_after * 1000:.0f} ms)")

    def _watch(self) -> None:
        """The watchdog: every period, the states taken and their age checked, and zeros
        published once when the loop has not actuated for ``stale_after`` (it paused,
        ended or hangs: the controller would hold the last command); the loop's next
        command goes out again."""
        while self._running:
            self._waitset.wait(duration(seconds=self.dt))
            with self._lock:
                if not self._running:
                    return
                self._take_states()
                now = time.monotonic()
                self._check_stale(now)
                if self._commanding and now - self._actuated > self.settings.stale_after:
                    self._publish(np.zeros(self.model.nv))
                    self._commanding = False
                    self.last_measures.idle_stops += 1
                if now - self._called > self.settings.stale_after:
                    self._release_actuating()

    def _release_actuating(self) -> None:
        """The thread made real-time by :meth:`actuate` given its scheduling back (caller
        holds the lock); its next call makes it real-time again."""
        if self._actuating is not None:
            release_realtime(self._actuating)
            self._actuating = None
            self.last_measures.realtime = self._scheduling

    # --- the Plant protocol ---------------------------------------------------------
    def wait_for_state(self, timeout: float | None = None) -> np.ndarray:
        """The first (or last) state's configuration; ``ValueError`` saying why when none
        comes within ``timeout`` (default ``settings.start_timeout``) or it is refused."""
        limit = time.monotonic() + (self.settings.start_timeout if timeout is None else timeout)
        while True:
            with self._lock:
                self._take_states()
                if self._state_order is None and self._state_names:
                    raise ValueError(self._refused)
                if self._q is not None:
                    return self._q.copy()
                if self.last_measures.stopped:
                    raise ValueError(self.last_measures.stopped)
            if time.monotonic() > limit:
                raise ValueError(f"no joint state on {self.settings.state_topic} (ROS domain "
                                 f"{self.node.domain}) within "
                                 f"{self.settings.start_timeout:g} s")
            time.sleep(min(self.dt, 0.01))

    def reset(self, q: np.ndarray | None = None) -> None:
        """Zeros commanded, the stop cleared, then the first state awaited (``ValueError``
        naming the missing joints or the silent topic). ``q`` is ignored: the robot is
        where it is.

        Before the robot is commanded, the objects alive are collected and frozen
        (``gc.collect``, ``gc.freeze``): the cyclic collector's later passes do not scan
        them. A pass over a large heap stops the loop's thread for tens of milliseconds
        (a 39 ms pass seen in a run), while the robot's controller holds the last command
        and the robot moves on with it (21 um of hole error on the MuJoCo sim for 1.5 um
        without the pause; docs/ros2.md "Real-time threads"). :meth:`close` unfreezes
        them, unless another plant still holds the freeze (:mod:`.heap_freeze`): a cycle
        among them that died meanwhile is collected then."""
        with self._lock:
            self._stop("reset")
            self.last_measures = Ros2Measures(states=self.last_measures.states,
                                              realtime=self.last_measures.realtime)
            self._commanding = False
            self._q = None  # a fresh state is awaited, its names checked again
            self._in_flight.clear()
            self._state_names = []
            self._overruns = 0
            self._gave_up = False
        freeze_heap(self)
        self.wait_for_state()
        self._period_start = time.monotonic()

    def sense(self, q: np.ndarray) -> np.ndarray:
        """Where the robot is when the next command acts (model order; before any state,
        ``q``): its last state moved on by the commands in flight, ``q_s + sum(c_i) dt``
        over the last ``settings.command_latency`` commands (a velocity controller applies
        a command at its first update after receiving it, while the state it last sent
        already went out: one period; docs/ros2.md "Measured"). 0: the last state."""
        with self._lock:
            self._take_states()
            if self._q is None:
                return q.copy()
            if not self._in_flight:
                return self._q.copy()
            return pin.integrate(self.model, self._q, sum(self._in_flight) * self.dt)

    def actuate(self, qd: np.ndarray, q: np.ndarray,
                constraints: Sequence[Constraint]) -> np.ndarray:
        """``qd`` published (zeros once stopped, nothing before the first state), the
        period ended by the robot's next state (but not before half a period, nor after
        one and a half: a late robot does not hold the loop up, the watchdog judges it),
        the mean velocity from ``q`` to the state then received returned. The calling
        thread is made real-time at its first call (``settings.realtime_priority``) until
        it stops actuating for ``stale_after``, the plant closes, or :data:`OVERRUN_PERIODS`
        periods in a row ended without waiting (then until :meth:`reset`)."""
        with self._lock:
            if not self._gave_up and self._actuating != threading.get_native_id():
                self._release_actuating()
                self._actuating, words = hold_realtime(self.settings.realtime_priority)
                self.last_measures.realtime = f"{self._scheduling}; actuating: {words}"
            self._called = time.monotonic()
            fresh = self._fresh
            self._take_states()
            self._check_stale(time.monotonic())
            if self._q is not None:
                if not math.isfinite(sum(qd.tolist())):
                    self._stop("non-finite command")
                self._commanding = True
                self._actuated = time.monotonic()
                self._publish(np.zeros(self.model.nv) if self.last_measures.stopped else qd)
            self.last_measures.command_publishers = (
                self._command_listener.get_subscription_matched_status().current_count)
            if self._paced:
                self._paced = False
            else:
                self._end_period(fresh)
            if (self._overruns >= OVERRUN_PERIODS and self._actuating is not None
                    and self.settings.realtime_priority > 0):
                self._give_up_realtime()
            if self._q is None:
                return np.zeros(self.model.nv)
            return pin.difference(self.model, q, self._q) / self.dt

    def advance(self, qd: np.ndarray, q: np.ndarray, constraints: Sequence[Constraint],
                dt: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`actuate`, and the configuration its velocity takes ``q`` to over ``dt``
        (``pin.integrate``)."""
        moved = self.actuate(qd, q, constraints)
        return moved, pin.integrate(self.model, q, moved * dt)

    def _end_period(self, fresh: int) -> None:
        """Waits for a state newer than the ``fresh``-th, not ending the period sooner
        than half a period after the last one ended nor later than one and a half (caller
        holds the lock; the wait releases it); counts the periods in a row that ended
        without waiting."""
        earliest = self._period_start + 0.5 * self.dt
        latest = self._period_start + 1.5 * self.dt
        now = time.monotonic()
        waited = False
        while now < latest and (self._fresh == fresh or now < earliest):
            self._lock.wait(timeout=(earliest if self._fresh > fresh else latest) - now)
            self._take_states()
            now = time.monotonic()
            waited = True
        self._overruns = 0 if waited else self._overruns + 1
        self._period_start = now
        self._period_fresh = self._fresh

    def _give_up_realtime(self) -> None:
        """The actuating thread (the caller) given its own scheduling back for overruns,
        until :meth:`reset` (caller holds the lock): a ``SCHED_FIFO`` thread that never
        sleeps holds its core against every ordinary thread, and against a robot's
        controller of a priority not above it (docs/ros2.md "Real-time threads")."""
        self._release_actuating()
        self._gave_up = True
        self.last_measures.realtime = (
            f"{self._scheduling}; actuating: ordinary scheduling (SCHED_FIFO "
            f"{self.settings.realtime_priority} given up: {self._overruns} periods in a row "
            f"ended without waiting for the robot, the loop's tick overran them; again "
            f"at the next reset)")

    def pace(self) -> None:
        """The period ended here rather than in :meth:`actuate`: the robot's next state
        awaited as :meth:`actuate` would (a state newer than the last period's end, within
        half to one and a half periods), and the next :meth:`actuate` publishes and
        returns at once, with the mean velocity to the state received here, before its
        publish: the loop's ``q`` trails the robot by one period more than unpaced (a
        velocity step commanded at tick k returned at tick k+1; :meth:`sense`, the
        controller's input, is the same newest state in both; docs/ros2.md "The page
        over ROS 2"). The page calls it between its ticks, outside its lock, so the
        operator's input is not held up while the robot's clock paces the loop
        (docs/ros2.md "The page over ROS 2")."""
        with self._lock:
            self._take_states()
            self._end_period(self._period_fresh)
            self._paced = True

    def set_period(self, dt: float) -> None:
        """The loop's new period ``dt`` (s): the pacing and the watchdog's wait follow it
        (one robot on the wire keeps one plant, ``ValueError`` for a period that is not
        finite and positive)."""
        if not isinstance(dt, (int, float)) or not math.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        with self._lock:
            self.dt = float(dt)

    def measures(self) -> Ros2Measures:
        """The last period's (:class:`Ros2Measures`)."""
        return self.last_measures

    # --- the end --------------------------------------------------------------------
    def close(self) -> None:
        """Zeros published (when a command was), the watchdog ended, the node closed."""
        if self._closed:
            return
        self._closed = True
        with self._lock:
            self._running = False
            self._stop("closed")
            self._release_actuating()
        self._watchdog.join(timeout=1.0)
        atexit.unregister(self.close)
        self.node.close()
        release_heap(self)

    def __enter__(self) -> "Ros2Plant":
        return self

    def __exit__(self, *error: object) -> None:
        self.close()
