"""What the page draws of each constraint (docs/design.md section 5.5): its shape, colour,
world axis and error vector, registered here by constraint type.

A constraint carries only its math; a type the page draws registers a
:class:`ConstraintDrawing` (:func:`register_drawing`), and :func:`constraint_geometry` turns
a constraint at its link's placement into a :class:`ConstraintGeometry`, all in the world
frame, for the markers. The lookup walks the type's bases, so a subclass draws as its base
does and any type draws at least as :class:`constraints.Constraint` is registered: a grey
point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Generic, TypeVar

import numpy as np
import pinocchio as pin

from constraints import Barrier, Constraint, Hole, Plane, PointLock

#: how the page draws a constraint's geometry (:attr:`ConstraintGeometry.shape`): a ring
#: around an axis, a flat square through a point with a normal, a point
SHAPES = ("ring", "plane", "point")

#: the constraint type a drawing is registered for
C = TypeVar("C", bound=Constraint)


@dataclass(frozen=True)
class ConstraintGeometry:
    """What the page draws of one constraint at a configuration, all in the world frame (m).

    Attributes
    ----------
    kind : the constraint's ``kind`` ("hole", "plane", ...).
    shape : how to draw the geometry: ``"ring"`` (around ``axis`` at ``anchor``),
        ``"plane"`` (through ``anchor``, normal ``axis``) or ``"point"`` (at ``anchor``).
    anchor : (3,) the geometry's reference point (hole centre, plane point, lock target):
        :attr:`constraints.Constraint.position`.
    point : (3,) the constrained point on the link.
    axis : (3,) unit world axis (a hole's link axis, a plane's normal), or None.
    error : (3,) from where the point should be to where it is (``point - error``
        satisfies the constraint); zero when satisfied, so zero for a barrier on its
        allowed side.
    color : display colour, RGB 0-255.
    label : human-readable name of the kind.
    allowed_side : (3,) unit world direction a one-sided constraint lets the point go
        (a barrier's normal), or None for an equality.
    """

    kind: str
    shape: str
    anchor: np.ndarray
    point: np.ndarray
    axis: np.ndarray | None
    error: np.ndarray
    color: tuple[int, int, int]
    label: str
    allowed_side: np.ndarray | None = None


def no_axis(constraint: Constraint, placement: pin.SE3) -> None:
    """No world axis (a point)."""
    return None


def error_along_directions(constraint: Constraint, placement: pin.SE3) -> np.ndarray:
    """The constraint's error as a world vector, ``R_a C^T e`` (docs/design.md section 3);
    its norm is the constraint's ``violation`` for an equality."""
    return placement.rotation @ (constraint.directions(placement).T @ constraint.error(placement))


@dataclass(frozen=True)
class ConstraintDrawing(Generic[C]):
    """How the page draws constraints of one type.

    Attributes
    ----------
    shape : one of :data:`SHAPES`.
    color : RGB 0-255.
    axis : the geometry's unit world axis at the link's placement (a hole's link axis, a
        plane's normal), or None; a one-sided constraint allows the side it points to.
    error : the world vector from where the point should be to where it is.
    """

    shape: str
    color: tuple[int, int, int]
    axis: Callable[[C, pin.SE3], np.ndarray | None] = no_axis
    error: Callable[[C, pin.SE3], np.ndarray] = error_along_directions

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"unknown shape {self.shape!r}: one of {', '.join(SHAPES)}")


#: constraint type -> how it is drawn (the nearest registered base of a type decides)
DRAWINGS: dict[type[Constraint], ConstraintDrawing[Any]] = {}


def register_drawing(constraint_type: type[C], drawing: ConstraintDrawing[C]) -> None:
    """Draw constraints of ``constraint_type`` (and of subclasses without their own) so."""
    DRAWINGS[constraint_type] = drawing


def drawing_of(constraint: Constraint) -> ConstraintDrawing[Any]:
    """How the page draws ``constraint``: its type's nearest registered drawing."""
    return next(DRAWINGS[kind] for kind in type(constraint).__mro__ if kind in DRAWINGS)


def constraint_geometry(constraint: Constraint, placement: pin.SE3) -> ConstraintGeometry:
    """Everything the page draws of ``constraint`` at its link's ``placement``, in the
    world frame."""
    drawing = drawing_of(constraint)
    axis = drawing.axis(constraint, placement)
    return ConstraintGeometry(
        kind=constraint.kind, shape=drawing.shape, anchor=constraint.position,
        point=constraint.point_world(placement), axis=axis,
        error=drawing.error(constraint, placement), color=drawing.color,
        label=constraint.label, allowed_side=None if constraint.is_equality else axis)


def link_axis_world(hole: Hole, placement: pin.SE3) -> np.ndarray:
    """A hole's link axis in the world (its ring is drawn around it)."""
    return placement.rotation @ hole.link_axis


def plane_normal(plane: Plane, placement: pin.SE3) -> np.ndarray:
    """A plane's world normal."""
    return plane.normal.copy()


def barrier_error(barrier: Barrier, placement: pin.SE3) -> np.ndarray:
    """``min(d, 0) n``: zero on the allowed side, behind it back to the plane."""
    return min(0.0, barrier.signed_distance(placement)) * barrier.normal


register_drawing(Constraint, ConstraintDrawing("point", (128, 128, 128)))
register_drawing(Hole, ConstraintDrawing("ring", (255, 170, 0), link_axis_world))
register_drawing(Plane, ConstraintDrawing("plane", (60, 140, 255), plane_normal))
register_drawing(Barrier, ConstraintDrawing("plane", (230, 40, 40), plane_normal, barrier_error))
register_drawing(PointLock, ConstraintDrawing("point", (40, 170, 90)))
