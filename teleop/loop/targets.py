"""The operator's targets as the loop takes them, and the cap on a commanded twist
(docs/design.md 5.1)."""

from __future__ import annotations

import math
from typing import Sequence, Union

import numpy as np
import pinocchio as pin

#: An operator target: one pose for a single-EE robot, else one per ``robot.ee_frames`` entry.
Targets = Union[pin.SE3, Sequence[pin.SE3]]


def target_poses(target: Targets) -> list[pin.SE3]:
    """``target`` as a list of poses (a lone ``pin.SE3`` becomes a list of one)."""
    poses = [target] if isinstance(target, pin.SE3) else list(target)
    for pose in poses:
        if not isinstance(pose, pin.SE3):
            raise ValueError(f"a target must be a pin.SE3, got {type(pose).__name__}")
    return poses


def saturate_twist(twist: np.ndarray, max_linear: float, max_angular: float) -> np.ndarray:
    """Scale ``[v; w]`` uniformly so that ``|v| <= max_linear`` and ``|w| <= max_angular``;
    ``twist`` itself when it is within both (the common case)."""
    vx, vy, vz, wx, wy, wz = twist.tolist()
    # inside both caps by a margin that covers rounding: the common case, no norm computed
    if (vx * vx + vy * vy + vz * vz < 0.999 * max_linear * max_linear
            and wx * wx + wy * wy + wz * wz < 0.999 * max_angular * max_angular):
        return twist
    # the norms as np.linalg.norm computes them, without its call overhead
    linear = math.sqrt(float(np.dot(twist[:3], twist[:3])))
    angular = math.sqrt(float(np.dot(twist[3:], twist[3:])))
    scale = min(1.0, max_linear / max(linear, 1e-300), max_angular / max(angular, 1e-300))
    return twist if scale == 1.0 else twist * scale
