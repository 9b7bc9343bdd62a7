"""Sliding a constraint along its link: the random trocar placements of a variation
(docs/design.md 15.1.1).

A constraint type that may slide with its link registers a :class:`Sliding` here
(:func:`register_sliding`): the world axis ``a`` it slides along at a configuration, and
the constructor fields in link coordinates that move with it. :func:`slid_along_link` then
moves the geometry's world reference point by ``d = offset a`` and a point fixed on the link
by ``R_a^T d``, so the constraint's error at that configuration stays what it was. A type
without one (nor a base with one) does not slide.
"""

from __future__ import annotations

from typing import Any, Protocol, TypeVar

import numpy as np

from constraints import Constraint, Hole, Plane, PointLock, RobotLike
from constraints.base import link_axis_of
from constraints.kinematics import frame_placement
from constraints.validation import as_number

#: the constraint type a sliding piece is registered for
C = TypeVar("C", bound=Constraint, contravariant=True)


class Sliding(Protocol[C]):
    """How constraints of one type slide along their link."""

    def axis(self, constraint: C, robot: RobotLike, q: np.ndarray) -> np.ndarray:
        """Unit world axis (at ``q``) the geometry slides along with its link."""
        ...

    def link_fields(self, constraint: C, link_shift: np.ndarray) -> dict[str, Any]:
        """The constructor fields in link coordinates, moved by ``link_shift`` (a point
        fixed on the link)."""
        ...


class AlongLinkAxis:
    """A hole: its centre slides along the link axis (the hole's own ``link_axis``), still
    on it; nothing of it is in link coordinates but the axis, which does not move."""

    def axis(self, hole: Hole, robot: RobotLike, q: np.ndarray) -> np.ndarray:
        """``R_a link_axis`` at ``q``."""
        return frame_placement(robot.model, q, hole.link).rotation @ hole.link_axis

    def link_fields(self, hole: Hole, link_shift: np.ndarray) -> dict[str, Any]:
        """None."""
        return {}


class WithLinkPoint:
    """A constraint on a point fixed on the link (a plane, a barrier, a point lock): the
    link point and the geometry slide together along the link's long axis
    (``link_axis_of`` the robot)."""

    def axis(self, constraint: Plane | PointLock, robot: RobotLike,
             q: np.ndarray) -> np.ndarray:
        """``R_a a_link`` at ``q``."""
        rotation = frame_placement(robot.model, q, constraint.link).rotation
        return rotation @ link_axis_of(robot, constraint.link)

    def link_fields(self, constraint: Plane | PointLock,
                    link_shift: np.ndarray) -> dict[str, Any]:
        """The link point, moved with the geometry."""
        return {"link_point": (constraint.link_point + link_shift).tolist()}


#: constraint type -> how it slides; a type not here (nor any of its bases) does not
SLIDINGS: dict[type[Constraint], Sliding[Any]] = {}


def register_sliding(constraint_type: type[C], sliding: Sliding[C]) -> None:
    """Let constraints of ``constraint_type`` (and of subclasses without their own) slide."""
    SLIDINGS[constraint_type] = sliding


def sliding_of(constraint: Constraint) -> Sliding[Any] | None:
    """How ``constraint`` slides, or None (the type's nearest registered base decides)."""
    for kind in type(constraint).__mro__:
        sliding = SLIDINGS.get(kind)
        if sliding is not None:
            return sliding
    return None


def sliding_axis(constraint: Constraint, robot: RobotLike, q: np.ndarray) -> np.ndarray | None:
    """Unit world axis ``a`` (at ``q``) along which ``constraint`` may slide with its link,
    its error unchanged; None: it does not slide."""
    sliding = sliding_of(constraint)
    return None if sliding is None else sliding.axis(constraint, robot, q)


def slid_along_link(constraint: Constraint, robot: RobotLike, q: np.ndarray,
                    offset: float) -> Constraint:
    """A new constraint like ``constraint`` slid ``offset`` m along :func:`sliding_axis`: its
    world reference point moves by ``d = offset a``, a point fixed on the link by
    ``R_a^T d``, so its error at ``q`` stays what it was; ``constraint`` itself when it does
    not slide."""
    sliding = sliding_of(constraint)
    if sliding is None:
        return constraint
    world_shift = as_number(offset, "offset") * sliding.axis(constraint, robot, q)
    link_shift = frame_placement(robot.model, q, constraint.link).rotation.T @ world_shift
    return Constraint.from_dict({
        **constraint.to_dict(),
        constraint.position_attribute: (constraint.position + world_shift).tolist(),
        **sliding.link_fields(constraint, link_shift)})


register_sliding(Hole, AlongLinkAxis())
register_sliding(Plane, WithLinkPoint())
register_sliding(PointLock, WithLinkPoint())
