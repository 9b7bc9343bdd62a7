"""Which part of a target the robot cannot reach, why, and the one action that helps, in
plain words (docs/design.md section 20.4).

The part is what the EE's task mode asks and the robot does not meet: its position, its
roll about the tool axis (``position_roll``) or its orientation (``pose``). The cause is
the most specific the step tells: a joint at its limit, a singularity (the controller
damped its task), the ports on the chain (a full pose asked through a port, which takes
two of the arm's freedoms), else the constraints themselves. The action is the one that
removes that cause.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from teleop.loop.task_modes import PORT_DIRECTIONS, TASK_MODES, roll_angle

from .limits import ON_TARGET
from .status import Limitation

#: an orientation (or roll) is reached within this angle (rad): 0.5 degrees
ON_TARGET_ANGLE = math.radians(0.5)


def asked_angle(mode: str, placement: pin.SE3, target: pin.SE3) -> float:
    """The angle (rad) between the EE at ``placement`` and ``target`` in what ``mode``
    asks of the orientation: all of it (``pose``), the roll about the tool axis
    (``position_roll``, the twist of ``R_e^T R*``), nothing (``position``)."""
    turn = placement.rotation.T @ target.rotation
    if mode == "pose":
        return float(np.linalg.norm(pin.log3(turn)))
    if mode == "position_roll":
        return abs(roll_angle(turn))
    return 0.0


def shortfall_words(mode: str, position_error: float, angle_error: float, stalled: bool,
                    info, joint_names: Sequence[str], ports: Sequence[str]) -> str:
    """What EE cannot reach of its target in mode ``mode`` and why, with the action that
    helps; ``""`` when it reaches what it is asked, or is still moving there.

    ``position_error`` (m) and ``angle_error`` (rad, :func:`asked_angle`) are what is left;
    ``stalled`` whether the EE no longer approaches its target; ``info`` the controller's
    :class:`controllers.SolveInfo`; ``ports`` the names of the equalities on the EE's
    chain that take two freedoms or more (a port)."""
    parts = []
    if position_error > ON_TARGET and stalled:
        parts.append(f"position {1e3 * position_error:.1f} mm")
    status = getattr(info.status, "value", str(info.status))
    if angle_error > ON_TARGET_ANGLE and status in ("least_squares", "scaled"):
        what = "roll" if mode == "position_roll" else "orientation"
        parts.append(f"{what} {math.degrees(angle_error):.1f} deg")
    if not parts:
        return ""
    joints = [joint_names[i] for i in info.saturated_joints if i < len(joint_names)]
    singular = info.damping > 0.0 or "singular" in info.message
    if mode == "pose" and ports:
        cause = (f"{', '.join(ports)} takes two of the arm's freedoms and the full pose "
                 f"six more, which leaves the arm none to spare here")
        action = f"set the task mode to {TASK_MODES['position_roll'].words} (what a port allows)"
    elif joints:
        cause = f"joint {', '.join(joints)} at {'its limit' if len(joints) == 1 else 'their limits'}"
        action = "bring the target back the way it came, or Home"
    elif singular:
        cause = "the arm is near a singularity (stretched out or folded)"
        action = "bring the target back the way it came, or Home"
    else:
        cause = "the constraints leave no motion towards it"
        action = "move the target, or the constraint, so that the link can pass"
    return f"{' and '.join(parts)} short of the target: {cause}; {action}"


def ports_on_chain(model: pin.Model, ee_frame_id: int,
                   constraints: Mapping[str, Constraint]) -> list[str]:
    """The names (keys of ``constraints``) of the equalities on the chain of the EE at
    ``ee_frame_id`` that take :data:`~teleop.loop.task_modes.PORT_DIRECTIONS` freedoms or
    more (a port)."""
    supports = model.supports[model.frames[ee_frame_id].parentJoint]
    return [name for name, constraint in constraints.items()
            if constraint.is_equality and constraint.dim >= PORT_DIRECTIONS
            and model.existFrame(constraint.link)
            and model.frames[model.getFrameId(constraint.link)].parentJoint in supports]


def explained(limitation: Limitation, shortfall: str, homing: str) -> Limitation:
    """``limitation`` in plain words: what "Home" does (``homing``), else what part of
    the target is short (``shortfall``), the step's words in ``details``; as it was when
    there is neither."""
    words = homing or shortfall
    if not words or limitation.status == "failed":
        return limitation
    return Limitation(limitation.status, words, limitation.distance, limitation.words)
