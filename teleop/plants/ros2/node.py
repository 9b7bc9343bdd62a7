"""A ROS 2 node's endpoints without rclpy (docs/ros2.md, "On the wire"): a Cyclone DDS
participant on the domain ``ROS_DOMAIN_ID`` (0 unset), topics named as ROS 2 mangles
them (``/joint_states`` is the DDS topic ``rt/joint_states``), ROS 2's default QoS
(reliable, keep last 10, volatile) and each endpoint's type hash in its user data, as
``rmw_cyclonedds_cpp`` writes it."""

from __future__ import annotations

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from .messages import ros_name
from .names import dds_topic, domain_id
from .type_hashes import user_data

#: ROS 2's default QoS depth (``rmw_qos_profile_default``: keep last 10).
DEFAULT_DEPTH = 10

def endpoint_qos(message_type: type, depth: int = DEFAULT_DEPTH) -> Qos:
    """ROS 2's default QoS for a reader or writer of ``message_type``, with its type hash
    in the user data."""
    return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
               Policy.History.KeepLast(depth), Policy.Durability.Volatile,
               Policy.Userdata(user_data(ros_name(message_type))))


class Ros2Node:
    """One participant and its endpoints (closed together by :meth:`close`).

    Parameters
    ----------
    domain : the ROS 2 domain id (None: ``ROS_DOMAIN_ID``, else 0).
    """

    def __init__(self, domain: int | str | None = None) -> None:
        self.domain = domain_id(domain)
        self.participant = DomainParticipant(self.domain)
        self._topics: dict[str, Topic] = {}

    def _topic(self, name: str, message_type: type) -> Topic:
        dds_name = dds_topic(name)
        topic = self._topics.get(dds_name)
        if topic is None:
            topic = self._topics[dds_name] = Topic(self.participant, dds_name, message_type)
        return topic

    def writer(self, name: str, message_type: type) -> DataWriter:
        """A writer on the ROS 2 topic ``name``."""
        return DataWriter(self.participant, self._topic(name, message_type),
                          qos=endpoint_qos(message_type))

    def reader(self, name: str, message_type: type) -> DataReader:
        """A reader of the ROS 2 topic ``name``."""
        return DataReader(self.participant, self._topic(name, message_type),
                          qos=endpoint_qos(message_type))

    def close(self) -> None:
        """The participant and every endpoint gone (peers see them leave)."""
        self._topics.clear()
        self.participant.__del__()
