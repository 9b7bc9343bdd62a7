"""The RIHS01 type hashes ROS 2 (Iron and later) expects in a DDS endpoint's user data,
``typehash=RIHS01_<64 hex>;`` (REP 2011): the SHA-256 of the message's type description,
computed by ``rosbags`` from the message definitions of ROS 2 Jazzy (``crtk_msgs``
registered from :data:`~teleop.plants.ros2.messages.OPERATING_STATE_DEFINITION`).
Humble ignores the user data; without it Iron and later log "Failed to parse type hash"."""

from __future__ import annotations

from functools import lru_cache

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .messages import OPERATING_STATE_DEFINITION


@lru_cache(maxsize=None)
def _store():
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(OPERATING_STATE_DEFINITION, "crtk_msgs/msg/OperatingState"))
    return store


def type_hash(ros_name: str) -> str:
    """``RIHS01_...`` of the message ``ros_name`` (``sensor_msgs/msg/JointState``);
    ``ValueError`` naming it when no store knows it."""
    store = _store()
    if ros_name not in store.fielddefs:
        raise ValueError(f"no ROS 2 message definition for {ros_name!r}")
    return str(store.hash_rihs01(ros_name))


def user_data(ros_name: str) -> bytes:
    """The endpoint user data ``rmw_cyclonedds_cpp`` writes: ``typehash=<hash>;``."""
    return f"typehash={type_hash(ros_name)};".encode()
