"""Where a ROS 2 robot is on the wire (docs/ros2.md, "Topics"): the joint states it
publishes and the commands it takes, a ros2_control ``JointGroupVelocityController`` or a
CRTK namespace, the domain, and the watchdog's limits."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

from constraints.limits import MAX_RESPONSE_TIME_S
from constraints.validation import as_number, short_repr

from .names import dds_topic, domain_id
from .realtime import LOOP_PRIORITY, check_priority

#: the most control periods :attr:`Ros2Settings.command_latency` predicts over
MAX_COMMAND_LATENCY = 10

#: :attr:`Ros2Settings.response_time` left out (s): the time constant ``1 / (2 pi 20 Hz)``
#: of a 20 Hz joint servo, the MuJoCo plant's default (``PlantSettings().response_time``),
#: so a robot over ROS 2 and the simulated one the damper counts on alike until the user
#: gives the robot's own (docs/ros2.md, "The collision damper's response time")
DEFAULT_RESPONSE_TIME = 1.0 / (2.0 * math.pi * 20.0)


@dataclass(frozen=True)
class Ros2Settings:
    """The ROS 2 side of a :class:`~teleop.plants.ros2.Ros2Plant`.

    Attributes
    ----------
    joint_states : the ``sensor_msgs/JointState`` topic (``joint_state_broadcaster``'s).
    command_topic : the ``JointGroupVelocityController``'s ``/<controller>/commands``.
    command_joints : the controller's ``joints`` parameter, in order (the message's
        order); empty: the robot model's joints in their order.
    crtk : a CRTK namespace (``/PSM1``): ``<ns>/measured_js`` and ``<ns>/servo_jv``
        replace the two topics above, ``<ns>/operating_state``'s state is kept in the
        plant's measures; empty: ros2_control.
    domain : the ROS 2 domain id (None: ``ROS_DOMAIN_ID``, else 0).
    stale_after : a state older than this (s) stops the robot (the watchdog).
    start_timeout : how long (s) :meth:`Ros2Plant.reset` waits for the first state.
    command_latency : control periods between a state the robot sends and the update
        that applies the command computed from it (ros2_control: 1, the command waits
        for the controller's next update); :meth:`Ros2Plant.sense` moves the state on by
        the commands in flight (0: the state as received).
    realtime_priority : the ``SCHED_FIFO`` priority (1-99) of the threads on the wire
        (the thread that actuates, the watchdog, DDS's own), 40 by default: below
        ros2_control's ``controller_manager``, whose update thread runs at 50 (the
        simulated robot's default, as it plays the robot); 0: ordinary scheduling
        (:mod:`teleop.plants.ros2.realtime`).
    response_time : ``tau`` (s), how late the robot follows a velocity command (its
        servos' time constant), in [0, :data:`~constraints.limits.MAX_RESPONSE_TIME_S`]:
        what the collision damper counts on, ``1 / K = (d_i - d_s) / xi + tau``
        (docs/design.md 18.6), as the MuJoCo plant's ``1 / (2 pi servo_bandwidth)``;
        :data:`DEFAULT_RESPONSE_TIME` by default.
    """

    joint_states: str = "/joint_states"
    command_topic: str = "/forward_velocity_controller/commands"
    command_joints: tuple[str, ...] = ()
    crtk: str = ""
    domain: int | None = None
    stale_after: float = 0.05
    start_timeout: float = 5.0
    command_latency: int = 1
    realtime_priority: int = LOOP_PRIORITY
    response_time: float = DEFAULT_RESPONSE_TIME

    def __post_init__(self) -> None:
        """``ValueError`` naming the field: a topic ROS 2 refuses, a domain outside
        [0, 232], a time that is not finite and positive, joints named twice."""
        for name in ("joint_states", "command_topic"):
            dds_topic(getattr(self, name))
        if self.crtk:
            dds_topic(self.crtk)
        if self.domain is not None:
            object.__setattr__(self, "domain", domain_id(self.domain))
        for name in ("stale_after", "start_timeout"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
        if (isinstance(self.command_latency, bool) or not isinstance(self.command_latency, int)
                or not 0 <= self.command_latency <= MAX_COMMAND_LATENCY):
            raise ValueError(f"command_latency must be a whole number of periods in [0, "
                             f"{MAX_COMMAND_LATENCY}], got {self.command_latency!r}")
        check_priority(self.realtime_priority)
        object.__setattr__(self, "response_time", as_number(
            self.response_time, "response_time", 0.0, maximum=MAX_RESPONSE_TIME_S))
        joints = tuple(self.command_joints)
        if len(set(joints)) != len(joints):
            raise ValueError(f"command_joints names a joint twice: {list(joints)}")
        object.__setattr__(self, "command_joints", joints)

    @property
    def state_topic(self) -> str:
        """Where the joint states come from."""
        return self.crtk.rstrip("/") + "/measured_js" if self.crtk else self.joint_states

    @property
    def commands(self) -> str:
        """Where the velocity commands go."""
        return self.crtk.rstrip("/") + "/servo_jv" if self.crtk else self.command_topic

    def to_dict(self) -> dict:
        """The fields (a session header's or metrics.json's ``plant.ros2``)."""
        entry = asdict(self)
        entry["command_joints"] = list(self.command_joints)
        return entry

    @classmethod
    def from_dict(cls, data: object) -> "Ros2Settings":
        """The inverse of :meth:`to_dict` (``ValueError`` naming an unknown field)."""
        if not isinstance(data, dict):
            raise ValueError(f"ros2 must be an object, got {short_repr(data)}")
        unknown = sorted(set(data) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"ros2 has unknown fields {unknown}")
        entry = dict(data)
        if "command_joints" in entry:
            joints = entry["command_joints"]
            if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
                raise ValueError(f"ros2 command_joints must be a list of names, got "
                                 f"{short_repr(joints)}")
            entry["command_joints"] = tuple(joints)
        return cls(**entry)

    def describe(self) -> str:
        """One line for humans."""
        where = (f"CRTK {self.crtk}" if self.crtk
                 else f"{self.joint_states} -> {self.command_topic}")
        domain = "ROS_DOMAIN_ID" if self.domain is None else str(self.domain)
        return (f"ROS 2 robot ({where}, domain {domain}, stopped when the state is "
                f"{self.stale_after * 1000:g} ms old, response time "
                f"{self.response_time * 1000:.3g} ms)")
