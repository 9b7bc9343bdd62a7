"""Kinematic constraints on a point of the robot's chain.

Each constraint computes, at a configuration, its structure matrix ``S`` (the paper's
reparametrisation of the twist of ``F_a``), its joint-space rows ``A qd = b`` with drift
feedback, and its position error. See ``base.Constraint``. Each also describes itself
(``kind``, ``to_dict`` / ``Constraint.from_dict``, ``position`` / ``move_to``);
``registry.CONSTRAINT_TYPES`` lists the kinds. What each other layer does with a type
(drawing and placing it on the page, the plant's wall, sliding it, the CJM's affine form)
is a piece that layer registers by type.
"""

from .barrier import DEFAULT_BARRIER_GAIN, Barrier
from .base import (
    DEFAULT_GAIN,
    Constraint,
    ConstraintPoint,
    Parametrisation,
    RobotLike,
    structure_nullspace,
    structure_of,
    structure_paper,
)
from .hole import Hole
from .plane import Plane
from .point_lock import PointLock
from .registry import CONSTRAINT_TYPES, register

#: the built-in kinds, in the order error messages and the UI list them
BUILTIN_TYPES = (Hole, Plane, Barrier, PointLock)
for _type in BUILTIN_TYPES:
    register(_type)
del _type

__all__ = [
    "BUILTIN_TYPES",
    "Barrier",
    "CONSTRAINT_TYPES",
    "Constraint",
    "ConstraintPoint",
    "Parametrisation",
    "DEFAULT_BARRIER_GAIN",
    "DEFAULT_GAIN",
    "Hole",
    "Plane",
    "PointLock",
    "RobotLike",
    "register",
    "structure_nullspace",
    "structure_of",
    "structure_paper",
]
