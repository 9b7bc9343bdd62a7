"""A simulated robot served over ROS 2 (docs/ros2.md, "A simulated robot"): the MuJoCo or
the kinematic plant behind the topics of ros2_control's ``joint_state_broadcaster`` and a
``JointGroupVelocityController`` (or CRTK's ``measured_js``, ``servo_jv`` and
``operating_state``), so a ROS 2 stack, or this project's :class:`Ros2Plant` in another
process, drives it as it would the real robot.

Every period (wall clock) it publishes the joint state, takes the newest command and moves
the robot with it, ``q <- integrate(q, v dt)`` with ``v`` the plant's mean velocity for the
command (the command itself on the kinematic plant). Like the real controller it holds the
last command until another arrives; a command of the wrong length is ignored, as
ros2_control's forward controllers do.

With constraints (the holes of a scene or a scenario) the physics plant's walls act at
their ports, and each port's wall force on the instrument (world frame, N, at the port:
``PlantMeasures.port_forces``, docs/design.md 17.2) is published every period as a
``geometry_msgs/WrenchStamped`` on ``<port_forces>/port<i>`` (``i`` the port's index in
the constraints' order, frame ``world``, torque zero).

Its threads run real-time as a ros2_control ``controller_manager``'s update thread does
(``Ros2Settings.realtime_priority``, SCHED_FIFO 50 by default): DDS's threads, started so,
and the thread that runs :meth:`SimulatedRos2Robot.run` (:mod:`teleop.plants.ros2.realtime`)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pinocchio as pin
from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.util import duration

from teleop.cpu_guard import QUIET_RETAKE, SHARE, CpuGuard, Verdict
from teleop.plants.walls import wall_of
from teleop.sleep_until import sleep_until

from .joint_map import indices, model_joint_names
from .messages import (Float64MultiArray, Header, JointState, OperatingState, Time, Vector3,
                       Wrench, WrenchStamped)
from .node import Ros2Node
from .realtime import (OVERRUN_PERIODS, ThreadScheduling, make_realtime, scheduling_words,
                       started_realtime)
from .names import dds_topic
from .settings import Ros2Settings


#: periods whose start lateness :meth:`SimulatedRos2Robot.lateness_words` sums up (the
#: last 2 min at 500 Hz)
LATENESS_KEPT = 1 << 16


def port_force_topic(base: str, index: int) -> str:
    """The topic of port ``index``'s wall force under ``base`` (``/port_forces/port0``)."""
    return f"{base.rstrip('/')}/port{index}"


class SimulatedRos2Robot:
    """The robot of ``plant`` (a ``teleop.loop.Plant``, None: the kinematic one) on ROS 2.

    Parameters
    ----------
    robot : the ``teleop.Robot``.
    rate : its joint states' and its control rate (Hz).
    settings : the topics and the domain (:class:`Ros2Settings`).
    plant : the physics under it, None: ``q += v dt``.
    q0 : where it starts (default ``robot.q_home``).
    constraints : what the plant's walls act on (its holes' ports); the physics plant's
        port forces are published (None or empty: no port).
    port_forces : the ROS 2 namespace of the port force topics.
    lockstep : seconds each period waits, once the state is out, for a command (none
        already there): the command computed from that state acts in the same period,
        the two processes' scheduling taken out of the loop (what the transport alone
        costs, docs/ros2.md "Jitter"); 0: a real robot's behaviour, no wait.
    """

    def __init__(self, robot, rate: float, settings: Ros2Settings | None = None,
                 plant=None, q0: np.ndarray | None = None, constraints=None,
                 port_forces: str = "/port_forces", lockstep: float = 0.0) -> None:
        if not isinstance(rate, (int, float)) or not 0 < rate <= 10000:
            raise ValueError(f"rate must be in (0, 10000] Hz, got {rate!r}")
        self.constraints = list(constraints or ())
        if self.constraints and plant is None:
            raise ValueError("the kinematic robot has no wall at its ports: constraints need "
                             "the physics plant (--plant mujoco)")
        dds_topic(port_forces)
        if not isinstance(lockstep, (int, float)) or not 0.0 <= lockstep <= 1.0:
            raise ValueError(f"lockstep must be in [0, 1] s, got {lockstep!r}")
        self.lockstep = float(lockstep)
        self.model: pin.Model = robot.model
        self.dt = 1.0 / float(rate)
        self.settings = settings or Ros2Settings()
        self.names = model_joint_names(self.model)
        joints = self.settings.command_joints or tuple(self.names)
        self._to_model = indices(self.names, joints, "the controller's joints")
        self.plant = plant
        self.q = np.array(robot.q_home if q0 is None else q0, dtype=float)
        if plant is not None:
            plant.reset(self.q)
        self.command = np.zeros(self.model.nv)  # model order, held
        self.commands = 0
        #: the wire's jitter as the robot sees it (docs/ros2.md "Measured"): periods run;
        #: periods between the first command and the last with no new one (the last held,
        #: acting twice; those after the last command are the loop's end, not jitter);
        #: commands another arrived after within the same period (never acting); periods
        #: that started more than half a period late on the robot's own clock; periods whose
        #: work ran past the next one's deadline (the next counted from its end, so neither
        #: late nor in the lateness: a physics slower than the wall clock shows here)
        self.periods = 0
        self.held = 0
        self.superseded = 0
        self.late = 0
        self.overran = 0
        self._holding = 0  # periods with no new command since the last one
        #: how late each period :meth:`run` started began after its deadline (s), the last
        #: LATENESS_KEPT, and how many it started
        self._lateness = np.zeros(LATENESS_KEPT)
        self._timed = 0
        self.node, self._dds_scheduling = started_realtime(
            self.settings.realtime_priority, lambda: Ros2Node(self.settings.domain))
        #: how its threads run (the periods' thread's added by :meth:`run`)
        self.realtime = f"DDS: {self._dds_scheduling}"
        self._states = self.node.writer(self.settings.state_topic, JointState)
        crtk = bool(self.settings.crtk)
        self._command_type = JointState if crtk else Float64MultiArray
        self._commands = self.node.reader(self.settings.commands, self._command_type)
        self._command_arrived = WaitSet(self.node.participant)
        self._command_arrived.attach(ReadCondition(self._commands, SampleState.Any
                                                   | ViewState.Any | InstanceState.Any))
        self._operating = (self.node.writer(self.settings.crtk.rstrip("/") + "/operating_state",
                                            OperatingState) if crtk else None)
        ports = sum(wall_of(c) is not None for c in self.constraints)
        self.port_force_writers = [self.node.writer(port_force_topic(port_forces, i),
                                                    WrenchStamped) for i in range(ports)]
        self._stop = threading.Event()

    def _take_command(self) -> None:
        """The newest good command held; the jitter counts of the period."""
        taken = 0
        for sample in self._commands.take(64):
            values = (sample.velocity if isinstance(sample, JointState)
                      else getattr(sample, "data", None))
            if values is None or len(values) != len(self._to_model):
                continue
            command = np.asarray(values, dtype=float)[self._to_model]
            if np.all(np.isfinite(command)):
                self.command = command
                self.commands += 1
                taken += 1
        self.superseded += max(0, taken - 1)
        if taken:
            self.held += self._holding
            self._holding = 0
        else:
            self._holding += self.commands > 0

    def step(self) -> None:
        """One period: the state published, the newest command taken, the robot moved."""
        stamp = Header(stamp=Time.of(time.time()))
        self._states.write(JointState(header=stamp, name=self.names,
                                      position=[float(v) for v in self.q],
                                      velocity=[float(v) for v in self.command]))
        if self._operating is not None:
            self._operating.write(OperatingState(header=stamp, state="ENABLED", is_homed=True))
        if self.lockstep:
            self._command_arrived.wait(duration(seconds=self.lockstep))
        self._take_command()
        self.periods += 1
        moved = (self.command if self.plant is None
                 else self.plant.actuate(self.command, self.q, self.constraints))
        self.q = pin.integrate(self.model, self.q, moved * self.dt)
        if self.port_force_writers:
            world = Header(stamp=stamp.stamp, frame_id="world")
            forces = self.plant.measures().port_forces
            for writer, force in zip(self.port_force_writers, forces):
                writer.write(WrenchStamped(header=world, wrench=Wrench(
                    force=Vector3(*(float(f) for f in force)), torque=Vector3())))

    def run(self, duration: float | None = None) -> None:
        """Periods on the wall clock until :meth:`stop` (or ``duration`` seconds), the
        calling thread made real-time (``settings.realtime_priority``). Period ``k``
        starts at ``start + k dt``: the thread sleeps to that absolute deadline
        (:func:`~teleop.sleep_until.sleep_until`), as a ``controller_manager`` does, so
        neither the period's work nor a late wake-up shifts the next; a period that
        overran its deadline starts the count again from its end (no burst of periods
        to catch up: the robot would see them as one jump). A physics slower than the
        wall clock never sleeps: after
        :data:`~teleop.plants.ros2.realtime.OVERRUN_PERIODS` periods in a row with no
        time left the thread goes back to its own scheduling for the rest of the run, as
        the loop's does. One that sleeps too little holds its core as well: the
        :class:`~teleop.cpu_guard.CpuGuard` of the page's control thread gives real-time
        up while the periods take more than :data:`~teleop.cpu_guard.SHARE` of a CPU,
        until they ran :data:`~teleop.cpu_guard.QUIET_RETAKE` s under it. :attr:`realtime`
        says how the thread runs and why."""
        before, ordinary = ThreadScheduling.of_calling_thread(), scheduling_words()
        periods = make_realtime(self.settings.realtime_priority)
        holding = scheduling_words() != ordinary  # real-time by this call
        self.realtime = f"DDS: {self._dds_scheduling}; periods: {periods}"
        guard = CpuGuard()
        start = time.monotonic()
        deadline = start
        overruns = 0
        overran = False  # given up for overruns: ordinary for the rest of the run
        while not self._stop.is_set():
            now = time.monotonic()
            if duration is not None and now - start >= duration:
                return
            lateness = now - deadline
            self._lateness[self._timed % LATENESS_KEPT] = lateness
            self._timed += 1
            self.late += lateness > 0.5 * self.dt
            self.step()
            deadline += self.dt
            now = time.monotonic()
            if deadline > now:
                overruns = 0
            else:
                deadline, overruns = now, overruns + 1
                self.overran += 1
            if (overruns == OVERRUN_PERIODS and scheduling_words() != ordinary
                    and before.restore()):
                holding, overran = False, True
                self.realtime = (f"DDS: {self._dds_scheduling}; periods: {scheduling_words()} "
                                 f"({periods} given up: {overruns} periods in a row with no "
                                 f"time left, the physics slower than the wall clock)")
            verdict = Verdict.MID_WINDOW if overran else guard.check(holding)
            if verdict is Verdict.GIVE_UP and before.restore():
                holding = False
                self.realtime = (f"DDS: {self._dds_scheduling}; periods: {scheduling_words()} "
                                 f"({periods} given up: the periods took "
                                 f"{100 * guard.share:.0f} % of a CPU; again after "
                                 f"{QUIET_RETAKE:g} s under {100 * SHARE:.0f} %)")
            elif verdict is Verdict.RETAKE:
                periods = make_realtime(self.settings.realtime_priority)
                holding = scheduling_words() != ordinary
                self.realtime = f"DDS: {self._dds_scheduling}; periods: {periods}"
            sleep_until(deadline)

    def lateness_words(self) -> str:
        """How late the periods started after their deadlines (the last
        :data:`LATENESS_KEPT`): p50, p99 and the worst, in microseconds."""
        kept = self._lateness[:min(self._timed, LATENESS_KEPT)]
        if not kept.size:
            return "no period timed"
        p50, p99 = np.percentile(kept, (50, 99)) * 1e6
        return (f"started after their deadlines by p50 {p50:.0f} us, p99 {p99:.0f} us, worst "
                f"{kept.max() * 1e6:.0f} us")

    def jitter_words(self) -> str:
        """The jitter counts in one line."""
        return (f"{self.periods} periods, {self.commands} commands: {self.held} periods held "
                f"the last command (none new), {self.superseded} commands superseded in "
                f"their period, {self.late} periods started over half a period late, "
                f"{self.overran} periods overran their deadline, "
                f"{self.lateness_words()} (threads {self.realtime})")

    def stop(self) -> None:
        """:meth:`run` returns after its period."""
        self._stop.set()

    def close(self) -> None:
        """The node closed."""
        self.node.close()
