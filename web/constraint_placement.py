"""How the page places each constraint type on the robot as it is now (docs/design.md
section 5.5), registered here by constraint type.

A constraint carries only its math; a type the page offers registers a
:class:`ConstraintPlacement` (:func:`register_placement`): the inputs it takes
(:mod:`web.placement_fields`) and the ``place`` that builds it from their values. The
lookup walks the type's bases, so a subclass is placed as its base is (``place`` builds
the subclass); a type registered nowhere is not offered.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Generic, TypeVar

import numpy as np

from constraints import Barrier, Constraint, Hole, Plane, PointLock, RobotLike
from constraints.validation import as_unit_vector

from .placement_fields import ALONG_LINK, ON_ANY_LINK, ON_ARM, ON_LINK_POINT, PlacementField

#: the constraint type a placement is registered for
C = TypeVar("C", bound=Constraint)


@dataclass(frozen=True)
class ConstraintPlacement(Generic[C]):
    """What placing a constraint type takes.

    Attributes
    ----------
    fields : one input per keyword of ``place`` (exactly one of them a ``"link"``).
    place : ``place(constraint_type, robot, q, **values)``, a constraint of
        ``constraint_type`` where ``robot`` is at ``q``, from the inputs' values (checked
        by field type by the caller, :mod:`web.app.placing`).
    """

    fields: tuple[PlacementField, ...]
    place: Callable[..., C]


#: constraint type -> how it is placed (the nearest registered base of a type decides)
PLACEMENTS: dict[type[Constraint], ConstraintPlacement[Any]] = {}


def register_placement(constraint_type: type[C], placement: ConstraintPlacement[C]) -> None:
    """Offer constraints of ``constraint_type`` (and of subclasses without their own)
    on the page, placed so."""
    PLACEMENTS[constraint_type] = placement


def placement_of(constraint_type: type[Constraint]) -> ConstraintPlacement[Any] | None:
    """How the page places ``constraint_type``: its nearest registered base's placement,
    or None (the page does not offer it)."""
    return next((PLACEMENTS[kind] for kind in constraint_type.__mro__ if kind in PLACEMENTS),
                None)


def place(constraint_type: type[C], robot: RobotLike, q: np.ndarray, **values: Any) -> C:
    """A constraint of ``constraint_type`` where ``robot`` is at ``q``, from the values of
    its placement's fields; a type without a placement raises ``ValueError``."""
    placement = placement_of(constraint_type)
    if placement is None:
        raise ValueError(f"a {constraint_type.label} is not placed from the UI: its type "
                         "registers no placement")
    return placement.place(constraint_type, robot, q, **values)


def hole_on_link(hole_type: type[Hole], robot: RobotLike, q: np.ndarray, link: str,
                 distance: float) -> Hole:
    """:meth:`constraints.Hole.on_link`: a hole ``distance`` m along ``link``'s axis."""
    return hole_type.on_link(robot, q, distance, link=link)


def lock_on_link(lock_type: type[PointLock], robot: RobotLike, q: np.ndarray, link: str,
                 distance: float) -> PointLock:
    """:meth:`constraints.PointLock.on_link`: the point ``distance`` m along ``link``'s axis."""
    return lock_type.on_link(robot, q, distance=distance, link=link)


def plane_through_link_point(plane_type: type[Plane], robot: RobotLike, q: np.ndarray,
                             link: str, normal, distance: float | None = None,
                             link_point=None, offset: float = 0.0) -> Plane:
    """:meth:`constraints.Plane.through_link_point`: through a point of ``link``
    (``distance`` m along its axis, or ``link_point`` in its coordinates) moved ``offset``
    m against the unit world ``normal``; the point must then be on the plane, or on a
    barrier's allowed side."""
    normal = as_unit_vector(normal, f"{plane_type.label} normal")
    return plane_type.through_link_point(robot, q, normal, link_point=link_point,
                                         distance=distance, link=link, offset=offset)


#: a plane's world normal (a barrier's allowed side)
NORMAL = PlacementField("normal", "direction", "normal (world)", default=(0.0, 1.0, 0.0),
                        step=0.1, hint="in world coordinates; a barrier keeps the point on "
                                       "the side the normal points to")
#: how far a barrier lies behind its point
OFFSET = PlacementField("offset", "number", "offset (m)", default=0.01, step=0.005,
                        hint="how far the barrier lies behind the point, along the normal "
                             "(the point starts on its allowed side)")

register_placement(Hole, ConstraintPlacement((ON_ARM, ALONG_LINK), hole_on_link))
register_placement(Plane, ConstraintPlacement(
    (ON_ANY_LINK, ALONG_LINK, ON_LINK_POINT, NORMAL), plane_through_link_point))
register_placement(Barrier, ConstraintPlacement(
    (ON_ANY_LINK, ALONG_LINK, ON_LINK_POINT, NORMAL, OFFSET), plane_through_link_point))
register_placement(PointLock, ConstraintPlacement((ON_ARM, ALONG_LINK), lock_on_link))
