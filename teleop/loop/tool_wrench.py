"""The wrench at the tool the tool-frame laws take (docs/design.md section 21.2): the
plant's force/torque sensor, refused by name on a plant without one."""

from __future__ import annotations

import numpy as np


def tool_wrench(plant, ee: int) -> np.ndarray:
    """EE ``ee``'s sensed wrench from the environment, tool frame (6,: N, N m), from the
    plant's last period; ``ValueError`` naming the plant when it has no force/torque
    sensor (the kinematic plant, a plant without tissue)."""
    if not getattr(plant, "has_force_sensor", False):
        name = "the kinematic plant" if plant is None else type(plant).__name__
        raise ValueError(f"{name} has no force/torque sensor: the tool-frame force laws "
                         f"need the mujoco plant with a tissue")
    wrenches = plant.measures().tool_wrenches
    if wrenches.shape[0] <= ee:
        raise ValueError(f"{type(plant).__name__} senses no wrench at EE {ee}: its force/torque "
                         f"sensors come with a tissue (tissues=...)")
    return wrenches[ee]
