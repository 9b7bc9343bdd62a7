"""What the operator commands of each end effector: its task mode (docs/design.md
section 20).

A task mode selects rows of the EE's body twist ``V_e = [v; w]`` (``LOCAL``, the EE's
own axes, linear first):

* ``pose``: all six, the full pose;
* ``position_roll``: the position ``v`` and the roll ``w_z`` about the tool axis (the EE
  frame's z), what a trocar's port allows an instrument (the tip moves anywhere, the
  instrument turns about its own axis, the shaft's direction follows the port);
* ``position``: the position ``v`` alone.

The rows left out are not asked: the controllers take the mode as the diagonal task
weight ``W`` (1 on the selected rows, 0 on the others, :func:`task_weight`), so the CJM
leaves them to its null space and the posture (section 4.5), the QP to its posture stage
(section 10.1) and mink to its posture task (section 10.5), alike. The loop fits the
operator's target to the mode (:func:`fit_target`): the orientation it does not ask for
follows the robot, so that no error in an unselected row enters the command through the
coupling of ``log6``'s linear part to the rotation.

``auto`` resolves per EE to what its chain's constraints allow (:func:`port_task_modes`):
``position_roll`` when equalities on the chain remove two directions or more (a hole,
a point lock), ``pose`` otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint


@dataclass(frozen=True)
class TaskMode:
    """One task mode: its name, the rows of the body twist it asks for (a 0/1 weight of
    6 entries, linear first), the words an operator reads, and its fitting of a target
    (:func:`fit_target`)."""

    name: str
    rows: tuple[float, float, float, float, float, float]
    words: str


#: The task modes, in the order the UI lists them.
TASK_MODES: dict[str, TaskMode] = {
    mode.name: mode for mode in (
        TaskMode("pose", (1.0, 1.0, 1.0, 1.0, 1.0, 1.0), "full pose"),
        TaskMode("position_roll", (1.0, 1.0, 1.0, 0.0, 0.0, 1.0),
                 "position and roll about the tool axis"),
        TaskMode("position", (1.0, 1.0, 1.0, 0.0, 0.0, 0.0), "position only"),
    )}

#: The mode that resolves per EE to what its chain's constraints allow.
AUTO = "auto"

#: Directions an EE's chain loses to equalities from which ``auto`` asks for position and
#: roll instead of the full pose (a hole's 2: the shaft's direction follows the port).
PORT_DIRECTIONS = 2


def task_mode(name: object) -> TaskMode:
    """The :class:`TaskMode` called ``name``; ``ValueError`` naming the known ones."""
    if not isinstance(name, str) or name not in TASK_MODES:
        raise ValueError(f"unknown task mode {name!r}; one of {', '.join(TASK_MODES)} "
                         f"(or {AUTO!r})")
    return TASK_MODES[name]


def task_modes(names: object, count: int) -> tuple[str, ...]:
    """``names`` as one mode name per EE (``count`` of them): a single name applies to
    every EE; ``ValueError`` for an unknown name or a wrong count. No ``auto`` here:
    :func:`port_task_modes` resolves it."""
    listed = [names] * count if isinstance(names, str) else list(names)  # type: ignore[call-overload]
    if len(listed) != count:
        raise ValueError(f"expected {count} task modes, one per end effector, got {len(listed)}")
    return tuple(task_mode(name).name for name in listed)


def task_weight(names: Sequence[str]) -> np.ndarray:
    """The controllers' diagonal task weight ``W`` of modes ``names`` (one per EE): 6
    entries per EE, 1 on the rows the mode asks for, 0 on the others."""
    return np.concatenate([np.array(task_mode(name).rows) for name in names])


def roll_angle(rotation: np.ndarray) -> float:
    """The angle in [-pi, pi] of ``rotation``'s twist about z in its swing-twist
    decomposition ``R = S Rz(phi)`` (``S`` about an axis perpendicular to z):
    ``phi = 2 atan2(q_z, q_w)`` of its unit quaternion, wrapped; 0 where the twist is
    undefined (a half turn of swing, ``q_w = q_z = 0``)."""
    quaternion = pin.Quaternion(rotation)
    w, z = quaternion.w, quaternion.z
    if math.hypot(w, z) < 1e-12:
        return 0.0
    return math.remainder(2.0 * math.atan2(z, w), 2.0 * math.pi)


def fit_target(name: str, target: pin.SE3, placement: pin.SE3) -> pin.SE3:
    """The target of mode ``name`` for an EE at ``placement``, from the operator's
    ``target``: its position always; for ``pose`` its rotation; for ``position_roll`` the
    EE's rotation turned about the tool axis by the roll between the two (``R_e Rz(phi)``,
    ``phi`` the :func:`roll_angle` of ``R_e^T R*``): ``R_e^T R_fit`` is a pure roll, so the
    pose twist's angular part is ``phi`` on the roll row alone; for ``position`` the EE's
    rotation (no angular twist)."""
    if name == "pose":
        return target
    rotation = placement.rotation
    if name == "position_roll":
        phi = roll_angle(rotation.T @ target.rotation)
        rotation = rotation @ pin.exp3(np.array([0.0, 0.0, phi]))
    return pin.SE3(rotation, target.translation)


def chain_directions(model: pin.Model, ee_frame_id: int, constraints: Sequence[Constraint],
                     frame_ids: Sequence[int]) -> int:
    """How many directions the equalities among ``constraints`` (on frames ``frame_ids``)
    remove from the chain of the EE at ``ee_frame_id``: the sum of their ``dim`` over
    those whose link the EE's chain carries (a frame not in the model is on no chain:
    the controllers refuse its constraint, naming it)."""
    supports = model.supports[model.frames[ee_frame_id].parentJoint]
    return sum(constraint.dim for constraint, frame in zip(constraints, frame_ids)
               if constraint.is_equality and frame < model.nframes
               and model.frames[frame].parentJoint in supports)


def port_task_modes(robot, constraints: Sequence[Constraint]) -> tuple[str, ...]:
    """``auto`` resolved per EE of ``robot.ee_frames``: ``position_roll`` when the
    equalities on its chain remove :data:`PORT_DIRECTIONS` or more directions, else
    ``pose``."""
    model = robot.model
    frame_ids = [model.getFrameId(constraint.link) for constraint in constraints]
    return tuple("position_roll" if chain_directions(model, ee, constraints, frame_ids)
                 >= PORT_DIRECTIONS else "pose" for ee in robot.ee_frame_ids)
