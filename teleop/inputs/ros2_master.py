"""A master arm on ROS 2 as an input source (docs/ros2.md, "A master on ROS 2"; docs/design.md
section 19): its CRTK ``servo_cp`` (``geometry_msgs/PoseStamped``) is the pose sample, in
the device's frame as a network master's; the feedback wrench the UDP master gets (the
spring towards the robot and the walls' terms, :mod:`.feedback`, plus the tip's contact
wrench when a contact law runs) goes out on ``servo_cf`` (``WrenchStamped``) at each
control tick that computes one.

A pose is refused as a network master's is (:func:`.protocol.decode_command`): a number
that is not finite (``not_finite``), a position farther than
:data:`~.protocol.MAX_DEVICE_POSITION` from the device's origin or a quaternion whose norm
is outside :data:`~.protocol.QUATERNION_NORM` (``out_of_range``); the quaternion is
normalised. Silence releases it after the app's timeout (``watchdog``): a CRTK master
streams ``servo_cp`` even at rest. DDS has no authentication: loopback or a closed network
(docs/ros2.md)."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState, WaitSet
from cyclonedds.util import duration

from teleop.plants.ros2.messages import PoseStamped, Vector3, Wrench, WrenchStamped
from teleop.plants.ros2.names import dds_topic
from teleop.plants.ros2.node import Ros2Node

from .protocol import MAX_DEVICE_POSITION, QUATERNION_NORM, FeedbackState
from .source import InputSample, InputSource

#: how long the receiving thread waits for a sample before it checks it should stop (s)
POLL = 0.05


class Ros2Master(InputSource):
    """A CRTK master: ``<namespace>/servo_cp`` in, ``<namespace>/servo_cf`` out.

    Parameters
    ----------
    namespace : the master's CRTK namespace (``/MTMR``).
    ee : the index of the end effector it drives.
    domain : the ROS 2 domain id (None: ``ROS_DOMAIN_ID``, else 0).
    """

    renders_feedback = True

    def __init__(self, namespace: str, ee: int = 0, domain: int | None = None) -> None:
        dds_topic(namespace)  # ValueError naming a namespace ROS 2 refuses
        super().__init__(f"ros2:{namespace}", ee)
        self.namespace = namespace.rstrip("/")
        self.node = Ros2Node(domain)
        self._poses = self.node.reader(self.namespace + "/servo_cp", PoseStamped)
        self._wrenches = self.node.writer(self.namespace + "/servo_cf", WrenchStamped)
        self._waitset = WaitSet(self.node.participant)
        self._waitset.attach(ReadCondition(self._poses, SampleState.Any | ViewState.Any
                                           | InstanceState.Any))
        self._running = False
        self._thread: threading.Thread | None = None
        self._sequence = 0
        self._closed = False

    def start(self) -> None:
        """The receiving thread."""
        if self._thread is None:
            self._running = True
            self._thread = threading.Thread(target=self._receive, name=self.name, daemon=True)
            self._thread.start()

    def _receive(self) -> None:
        while self._running:
            self._waitset.wait(duration(seconds=POLL))
            if not self._running:
                return
            for message in self._poses.take(64):
                if isinstance(message, PoseStamped):
                    self._take(message, time.perf_counter())

    def _take(self, message: PoseStamped, arrival: float) -> None:
        """One ``servo_cp``: offered as a pose sample, or counted by why it is refused."""
        p, o = message.pose.position, message.pose.orientation
        values = [p.x, p.y, p.z, o.w, o.x, o.y, o.z]
        if not all(math.isfinite(v) for v in values):
            self.count("not_finite")
            return
        norm = math.sqrt(sum(v * v for v in values[3:]))
        if (math.hypot(*values[:3]) > MAX_DEVICE_POSITION
                or not QUATERNION_NORM[0] <= norm <= QUATERNION_NORM[1]):
            self.count("out_of_range")
            return
        values[3:] = [v / norm for v in values[3:]]
        self._sequence += 1
        self.offer(InputSample("pose", tuple(values), 0, self._sequence, arrival))

    def set_feedback(self, wrench: np.ndarray, state: FeedbackState,
                     port_force_measured: bool) -> None:
        """``wrench`` (force N, torque N m, device frame) on ``servo_cf``; zeros while the
        master does not drive its EE (clutched, or released by the watchdog)."""
        if self._closed:
            return
        values = ([float(w) for w in wrench] if state == FeedbackState.FOLLOWING
                  else [0.0] * 6)
        if not all(math.isfinite(v) for v in values):
            values = [0.0] * 6
        self._wrenches.write(WrenchStamped(wrench=Wrench(force=Vector3(*values[:3]),
                                                         torque=Vector3(*values[3:]))))

    def close(self) -> None:
        """A zero wrench published, the thread stopped, the node closed."""
        if self._closed:
            return
        self.set_feedback(np.zeros(6), FeedbackState.HELD, False)
        self._closed = True
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self.node.close()
