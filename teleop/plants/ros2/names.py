"""ROS 2's names on DDS (docs/ros2.md, "On the wire"): a topic ``/joint_states`` is the DDS
topic ``rt/joint_states``; the domain is ``ROS_DOMAIN_ID`` (0 unset). No DDS library here:
the settings check their names without one."""

from __future__ import annotations

import os

#: The largest domain id ROS 2 accepts on Linux (docs/ros2.md, "Domain").
MAX_DOMAIN_ID = 232


def dds_topic(name: str) -> str:
    """The DDS name of the ROS 2 topic ``name``: ``rt/`` and the name without its leading
    slash (``/arm/servo_jv`` -> ``rt/arm/servo_jv``); ``ValueError`` on a name ROS 2
    refuses (empty, a space, ``//``, a trailing slash)."""
    if not isinstance(name, str) or not name.strip("/"):
        raise ValueError(f"a ROS 2 topic needs a name, got {name!r}")
    if name.endswith("/") or "//" in name or any(c.isspace() for c in name):
        raise ValueError(f"{name!r} is not a ROS 2 topic name")
    return "rt/" + name.lstrip("/")


def domain_id(value: int | str | None = None) -> int:
    """The ROS 2 domain: ``value``, else ``ROS_DOMAIN_ID``, else 0; ``ValueError`` naming
    it outside [0, :data:`MAX_DOMAIN_ID`]."""
    if value is None:
        value = os.environ.get("ROS_DOMAIN_ID", "") or 0
    try:
        number = int(value)
    except (TypeError, ValueError):
        raise ValueError(f"ROS_DOMAIN_ID must be an integer, got {value!r}") from None
    if not 0 <= number <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS_DOMAIN_ID must be in [0, {MAX_DOMAIN_ID}], got {number}")
    return number
