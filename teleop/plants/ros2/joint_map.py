"""Joints matched by name between the robot model and a ROS 2 message (docs/ros2.md,
"Joints"): never by position, since ``joint_state_broadcaster`` publishes in its own order
and a controller takes its ``joints`` parameter's."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin


def model_joint_names(model: pin.Model) -> list[str]:
    """The model's joints in velocity order; ``ValueError`` naming a joint with other than
    one coordinate (a ROS 2 joint state carries one position per name)."""
    names = []
    for joint in range(1, model.njoints):
        if model.nqs[joint] != 1 or model.nvs[joint] != 1:
            raise ValueError(f"joint {model.names[joint]} has {model.nqs[joint]} coordinates: "
                             f"a ROS 2 robot's joints have one each")
        names.append(model.names[joint])
    return names


def indices(wanted: Sequence[str], given: Sequence[str], where: str) -> np.ndarray:
    """For each name of ``wanted`` its index in ``given``; ``ValueError`` naming the ones
    ``where`` does not carry."""
    position = {name: i for i, name in enumerate(given)}
    missing = [name for name in wanted if name not in position]
    if missing:
        raise ValueError(f"{where} does not carry the joints {missing} "
                         f"(it has {list(given)})")
    return np.array([position[name] for name in wanted], dtype=int)
