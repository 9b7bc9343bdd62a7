"""The robot's end effectors as the operator names them: an index or a frame name of
``robot.ee_frames`` (docs/design.md section 11)."""

from __future__ import annotations

import numpy as np

from teleop.robots import Robot


def ee_index(robot: Robot, ee) -> int:
    """``ee`` (an index or a name of ``robot.ee_frames``) as an index; else ``ValueError``."""
    frames = robot.ee_frames
    if isinstance(ee, str) and ee in frames:
        return frames.index(ee)
    if isinstance(ee, (int, np.integer)) and not isinstance(ee, bool) and 0 <= ee < len(frames):
        return int(ee)
    raise ValueError(f"no end effector {ee!r}: this robot's are {list(frames)} "
                     f"(or their indices 0-{len(frames) - 1})")
